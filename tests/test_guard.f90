!> Unit tests of the flow guard (guard_check, src/dkt_diagnostics.f90): its row pass, which
!> vectorises along x, against the node-by-node scan it replaced for a healthy flow.
!>  - On a slab of pseudo-random populations (density 0.9-1.1, speeds up to Mach 0.35, a body
!>    force) in each storage form (8 bytes; 4 bytes as f_i - w_i; 4 bytes as f_i), the largest
!>    Mach number it returns is bitwise the largest of node_moments' values node by node, and
!>    a limit just above it passes;
!>  - a limit just below it fails with the Mach message naming the first node above the limit
!>    (row by row, x fastest), found as the scan finds it;
!>  - one NaN population, or an infinite one, anywhere fails as non-finite, naming that node,
!>    even when a faster node comes first;
!>  - finite populations whose density overflows to infinity (the row pass does not clear
!>    them) get the node-by-node verdict: no failure, as before (skipped in the checked build,
!>    which halts on the overflow in either pass);
!>  - in the checked build (floating-point traps on), a NaN or an infinity is reported, not
!>    trapped: the row pass does no arithmetic on it.
!> nx = 37 (not a multiple of a vector's width) and 11 rows: the row pass's remainder loops
!> are exercised.
program test_guard
  use ieee_arithmetic, only: ieee_value, ieee_quiet_nan, ieee_positive_inf
  use ieee_exceptions, only: ieee_get_halting_mode, ieee_overflow
  use mpi_f08, only: MPI_Init, MPI_Finalize, MPI_COMM_WORLD
  use dkt_kinds, only: wp, cs2
  use dkt_check, only: check, finish
  use dkt_lattice, only: equilibrium
  use dkt_domain, only: domain_t, domain_init, domain_free
  use dkt_store, only: lattice_t, lattice_allocate, lattice_free, lattice_set_node, &
                       lattice_get_node, lattice_set
  use dkt_fields, only: node_moments
  use dkt_diagnostics, only: guard_check
  use dkt_text, only: itoa
  implicit none
  integer, parameter :: NX = 37, NY = 11
  real(wp), parameter :: FORCE(2) = [1.0e-5_wp, -3.0e-5_wp]
  type(domain_t) :: dom
  character(len=:), allocatable :: err
  character(len=16), parameter :: FORMS(3) = ['8 bytes         ', '4 bytes shifted ', &
                                              '4 bytes         ']
  integer :: form
  logical :: overflow_halts

  call MPI_Init()
  call ieee_get_halting_mode(ieee_overflow, overflow_halts)
  call domain_init(dom, MPI_COMM_WORLD, NX, NY, .false., .false., 4, err)
  if (len(err) > 0) error stop err
  do form = 1, 3
    call one_form(form)
  end do
  call domain_free(dom)
  call finish()
  call MPI_Finalize()

contains

  subroutine one_form(form)
    integer, intent(in) :: form
    type(lattice_t) :: f
    real(wp) :: ref, mach, rho, ux, uy
    integer :: x, j, xa, ja
    character(len=:), allocatable :: failure, name
    name = trim(FORMS(form))//': '
    call lattice_allocate(f, dom%nxp, dom%nyl, form > 1, form == 2, .false., half=.false.)
    call fill(f)
    ! the node-by-node reference, and the first node above ref*(1 - 1e-3)
    ref = 0.0_wp
    xa = 0
    do j = 1, dom%nyl
      do x = 1, NX
        call node_moments(lattice_get_node(f, x, j), FORCE, rho, ux, uy)
        ref = max(ref, sqrt((ux*ux + uy*uy)/cs2))
      end do
    end do
    first: do j = 1, dom%nyl
      do x = 1, NX
        call node_moments(lattice_get_node(f, x, j), FORCE, rho, ux, uy)
        if (sqrt((ux*ux + uy*uy)/cs2) > ref*(1.0_wp - 1.0e-3_wp)) then
          xa = x
          ja = j
          exit first
        end if
      end do
    end do first

    call guard(f, ref*(1.0_wp + 1.0e-12_wp), mach, failure)
    call check(name//'the largest Mach number is the node-by-node one, bit for bit', &
               mach == ref .and. ref > 0.3_wp, mach - ref)
    call check(name//'a limit just above it passes', len(failure) == 0, 0.0_wp)
    call guard(f, ref*(1.0_wp - 1.0e-3_wp), mach, failure)
    call check(name//'a limit just below it fails with the Mach message at the first node', &
               index(failure, 'Mach number') == 1 .and. &
               index(failure, 'node ('//itoa(xa)//', '//itoa(ja)//')') > 0 .and. mach == ref, &
               real(xa, wp))

    call lattice_set(f, 30, 7, 4, ieee_value(1.0_wp, ieee_quiet_nan))
    call guard(f, ref*(1.0_wp - 1.0e-3_wp), mach, failure)
    call check(name//'a NaN population fails as non-finite at its node', &
               index(failure, 'non-finite value') == 1 .and. index(failure, 'node (30, 7)') > 0, &
               0.0_wp)
    call fill(f)
    call lattice_set(f, 2, 10, 8, ieee_value(1.0_wp, ieee_positive_inf))
    call guard(f, 1.0_wp, mach, failure)
    call check(name//'an infinite population fails as non-finite at its node', &
               index(failure, 'non-finite value') == 1 .and. index(failure, 'node (2, 10)') > 0, &
               0.0_wp)
    if (form == 1 .and. overflow_halts) then
      ! the checked build traps the overflow, in the node-by-node scan as in the row pass
      write (*, '(a)') 'SKIP an overflowing density (this build halts on overflow)'
    else if (form == 1) then
      ! densities of 1e308 + 1e308: the sum overflows, the populations and the velocity are
      ! finite (u = 0 after the division), so the node-by-node verdict is: no failure
      call fill(f)
      call lattice_set_node(f, 5, 3, [1.0e308_wp, 1.0e308_wp, 0.0_wp, 1.0e308_wp, 0.0_wp, &
                                      0.0_wp, 0.0_wp, 0.0_wp, 0.0_wp])
      call guard(f, ref*(1.0_wp + 1.0e-12_wp), mach, failure)
      call check(name//'an overflowing density falls back to the node-by-node verdict', &
                 len(failure) == 0 .and. mach == ref, mach - ref)
    end if
    call lattice_free(f)
  end subroutine one_form

  !> Equilibria of a density 0.9-1.1 and a velocity up to Mach 0.35 in a random direction,
  !! each population perturbed by up to 1e-3 (a fixed sequence: a linear congruence).
  subroutine fill(f)
    type(lattice_t), intent(inout) :: f
    integer(8) :: seed
    real(wp) :: fn(0:8), rho, speed, angle
    integer :: x, j, i
    seed = 12345
    do j = 1, dom%nyl
      do x = 1, NX
        rho = 0.9_wp + 0.2_wp*next(seed)
        speed = 0.35_wp*sqrt(cs2)*next(seed)
        angle = 6.283185307179586_wp*next(seed)
        fn = equilibrium(rho, speed*cos(angle), speed*sin(angle))
        do i = 0, 8
          fn(i) = fn(i)*(1.0_wp + 1.0e-3_wp*(next(seed) - 0.5_wp))
        end do
        call lattice_set_node(f, x, j, fn)
      end do
    end do
  end subroutine fill

  real(wp) function next(seed)
    integer(8), intent(inout) :: seed
    seed = modulo(seed*6364136223846793005_8 + 1442695040888963407_8, huge(seed))
    next = real(modulo(seed, 1000003_8), wp)/1000003.0_wp
  end function next

  subroutine guard(f, limit, mach, failure)
    type(lattice_t), intent(in) :: f
    real(wp), intent(in) :: limit
    real(wp), intent(out) :: mach
    character(len=:), allocatable, intent(out) :: failure
    call guard_check(dom, f, FORCE, limit, 100, 1.0_wp, 0.1_wp, 0.0_wp, mach, failure)
  end subroutine guard

end program test_guard

!> Unit tests of the 4-byte collision (lbm.precision = 'single_arith', src/dkt_mrt_sp.f90):
!>  - on random near-equilibrium populations, MRT and BGK, with and without a body force, the
!>    4-byte sweep in deviation form gives the 8-byte sweep of the same stored values to
!>    single-precision rounding of the deviations: at most 16 u_r max|f* - w| (u_r = 2^-24; a few
!>    roundings of moments up to ~10 times a deviation). Also at low Mach number (deviations
!>    ~1e-5), where a 4-byte collision of f_i itself would err by u_r w_i ~ 1e-8, i.e. ~1e3 u_r of
!>    the deviations: so the test fails if the constant w_i enters the 4-byte arithmetic;
!>  - the collision conserves mass, and momentum up to the body force it adds, to rounding
!>    (16 u_r of the sum of |d_i|);
!>  - in place, whole or in the time loop's three parts around the halo exchange, the 4-byte sweep
!>    has the bits of the 4-byte two-lattice sweep (the row buffers hold 4-byte deviations).
program test_mrt_sp
  use dkt_kinds, only: wp, sp
  use dkt_check, only: check, finish
  use dkt_lattice, only: ex, ey, w, equilibrium
  use dkt_store, only: lattice_t, lattice_allocate
  use dkt_mrt, only: collision_t, collision_init, stream_collide, e3_heat_flux_rate, sweep_t, &
                     sweep_init, sweep_rows
  use dkt_mrt_sp, only: collide_sp
  implicit none
  integer, parameter :: nx = 13, nxp = nx + 3
  real(wp), parameter :: u_r = 2.0_wp**(-24)
  integer :: k
  logical :: bgk, forced

  do k = 0, 3
    bgk = k >= 2
    forced = mod(k, 2) == 1
    call test_sweep_agrees_with_8_bytes(bgk, forced, 0.08_wp)
    call test_sweep_agrees_with_8_bytes(bgk, forced, 2.0e-5_wp)
    call test_conserves_mass_and_momentum(bgk, forced)
    call test_in_place_bits(bgk, forced)
  end do
  call finish()

contains

  function label(bgk, forced) result(s)
    logical, intent(in) :: bgk, forced
    character(len=:), allocatable :: s
    s = trim(merge('BGK', 'MRT', bgk))
    if (forced) s = s//' with body force'
  end function label

  !> Distinct MRT rates (or BGK at the same tau), the force scaled with the flow's amplitude.
  subroutine some_collision(coll, bgk, forced, amp)
    type(collision_t), intent(out) :: coll
    logical, intent(in) :: bgk, forced
    real(wp), intent(in) :: amp
    real(wp) :: force(2), s(0:8)
    force = 0.0_wp
    if (forced) force = amp*[2.5e-3_wp, -3.75e-3_wp]
    s = [0.0_wp, 1.1_wp, 1.25_wp, 0.0_wp, e3_heat_flux_rate(1/0.7_wp), 0.0_wp, &
         e3_heat_flux_rate(1/0.7_wp), 1/0.7_wp, 1/0.7_wp]
    call collision_init(coll, s, bgk, force)
  end subroutine some_collision

  !> A disturbed equilibrium on rows 0..ny+1 with density and velocity deviations of order amp.
  subroutine random_rows(f, ny, amp)
    integer, intent(in) :: ny
    real(wp), intent(out) :: f(0:nxp - 1, 0:ny + 1, 0:8)
    real(wp), intent(in) :: amp
    integer :: x, j
    real(wp) :: r(3), q(0:8)
    f = 0.0_wp
    do j = 0, ny + 1
      do x = 0, nx + 1
        call random_number(r)
        f(x, j, :) = equilibrium(1.0_wp + 0.6_wp*amp*(r(1) - 0.5_wp), amp*(r(2) - 0.5_wp), &
                                 amp*(r(3) - 0.5_wp))
        call random_number(q)
        f(x, j, :) = f(x, j, :) + 0.2_wp*amp*w*(q - 0.5_wp)
      end do
    end do
  end subroutine random_rows

  !> The 4-byte lattice storing fin - w, and fin replaced by the 8-byte values it stands for.
  subroutine stored(fin, a, ny)
    integer, intent(in) :: ny
    real(wp), intent(inout) :: fin(0:nxp - 1, 0:ny + 1, 0:8)
    type(lattice_t), intent(inout) :: a
    integer :: i
    do i = 0, 8
      a%s(:, :, i) = real(fin(:, :, i) - w(i), sp)
      fin(:, :, i) = real(a%s(:, :, i), wp) + w(i)
    end do
  end subroutine stored

  subroutine test_sweep_agrees_with_8_bytes(bgk, forced, amp)
    logical, intent(in) :: bgk, forced
    real(wp), intent(in) :: amp
    integer, parameter :: ny = 7
    type(collision_t) :: coll
    type(sweep_t) :: ws
    type(lattice_t) :: a, b
    real(wp) :: fin(0:nxp - 1, 0:ny + 1, 0:8), ref(0:nxp - 1, 0:ny + 1, 0:8), dev(1:nx, 1:ny, 0:8)
    real(wp) :: scale, err
    integer :: i
    character(len=16) :: amp_text
    call some_collision(coll, bgk, forced, amp)
    call random_rows(fin, ny, amp)
    call sweep_init(ws, nxp)
    call lattice_allocate(a, nxp, ny, .true., .true., arith4=.true., half=.false.)
    call lattice_allocate(b, nxp, ny, .true., .true., arith4=.true., half=.false.)
    call stored(fin, a, ny)
    ref = 0.0_wp
    call stream_collide(coll, fin, ref, nxp, nx, ny, 1, ny)
    do i = 0, 8
      dev(:, :, i) = ref(1:nx, 1:ny, i) - w(i)
    end do
    call sweep_rows(coll, ws, a, b, nx, ny, 1, ny)
    scale = maxval(abs(dev))
    err = maxval(abs(real(b%s(1:nx, 1:ny, :), wp) - dev))/(u_r*scale)
    write (amp_text, '(es8.1)') amp
    call check('4-byte sweep equals the 8-byte sweep to 16 u_r of the deviations (amplitude '// &
               trim(adjustl(amp_text))//'), in units of u_r max|f* - w|, '//label(bgk, forced), &
               err <= 16.0_wp, err)
  end subroutine test_sweep_agrees_with_8_bytes

  subroutine test_conserves_mass_and_momentum(bgk, forced)
    logical, intent(in) :: bgk, forced
    type(collision_t) :: coll
    real(wp) :: f(0:nxp - 1, 0:2, 0:8), before(0:8), after(0:8), err_m, err_j, size_d, jump(2)
    real(sp) :: d(0:8)
    integer :: x
    call some_collision(coll, bgk, forced, 0.08_wp)
    call random_rows(f, 1, 0.08_wp)
    err_m = 0.0_wp
    err_j = 0.0_wp
    do x = 1, nx
      d = real(f(x, 1, :) - w, sp)
      before = real(d, wp)
      call collide_sp(coll%c4, bgk, forced, d(0), d(1), d(2), d(3), d(4), d(5), d(6), d(7), d(8))
      after = real(d, wp)
      size_d = sum(abs(before)) + sum(abs(after))
      err_m = max(err_m, abs(sum(after) - sum(before))/(u_r*size_d))
      ! jx, jy gain the whole force (E1 with Guo's term; E4 likewise)
      jump = [sum(ex*after) - sum(ex*before), sum(ey*after) - sum(ey*before)] - &
             real([coll%c4%fx, coll%c4%fy], wp)
      err_j = max(err_j, maxval(abs(jump))/(u_r*size_d))
    end do
    call check('4-byte collision conserves mass to 16 u_r of sum |d_i|, '//label(bgk, forced), &
               err_m <= 16.0_wp, err_m)
    call check('4-byte collision conserves momentum (plus the body force) to 16 u_r, '// &
               label(bgk, forced), err_j <= 16.0_wp, err_j)
  end subroutine test_conserves_mass_and_momentum

  subroutine test_in_place_bits(bgk, forced)
    logical, intent(in) :: bgk, forced
    integer, parameter :: ny = 11
    type(collision_t) :: coll
    type(sweep_t) :: ws
    type(lattice_t) :: a, b, c
    real(wp) :: fin(0:nxp - 1, 0:ny + 1, 0:8)
    call some_collision(coll, bgk, forced, 0.08_wp)
    call random_rows(fin, ny, 0.08_wp)
    call sweep_init(ws, nxp)
    call lattice_allocate(a, nxp, ny, .true., .true., arith4=.true., half=.false.)
    call lattice_allocate(b, nxp, ny, .true., .true., arith4=.true., half=.false.)
    call lattice_allocate(c, nxp, ny, .true., .true., arith4=.true., half=.false.)
    call stored(fin, a, ny)
    c%s = a%s
    call sweep_rows(coll, ws, a, b, nx, ny, 1, ny)
    call sweep_rows(coll, ws, a, a, nx, ny, 1, ny)
    call check('4-byte sweep in place has the bits of two lattices, '//label(bgk, forced), &
               all(a%s(1:nx, 1:ny, :) == b%s(1:nx, 1:ny, :)), 0.0_wp)
    ! the time loop's three parts; the halo rows arrive after the first (corrupted until then)
    a%s = c%s
    c%s(:, 0, :) = -1.0_sp
    c%s(:, ny + 1, :) = -1.0_sp
    call sweep_rows(coll, ws, c, c, nx, ny, 3, ny - 2, keep=.true.)
    c%s(:, 0, :) = a%s(:, 0, :)
    c%s(:, ny + 1, :) = a%s(:, ny + 1, :)
    call sweep_rows(coll, ws, c, c, nx, ny, 1, 2, above_kept=.true.)
    call sweep_rows(coll, ws, c, c, nx, ny, ny - 1, ny, below_kept=.true.)
    call check('4-byte sweep in place in three parts around the halo has the bits, '// &
               label(bgk, forced), all(c%s(1:nx, 1:ny, :) == b%s(1:nx, 1:ny, :)), 0.0_wp)
  end subroutine test_in_place_bits

end program test_mrt_sp

!> Particle cost per step of a crowd of n disks: the two parts that depend on the number of
!> disks, timed apart, on the lattice_scene of tests/test_faults_scale.py (side x side free
!> disks of diameter 4 spacings, 6 spacings apart, in a closed box that just holds them).
!>  - contact: the E10–E11 force on every disk (particles_move with nothing moving, so that
!>    every disk's force is summed once and nothing is sent or refilled);
!>  - links: the boundary-link search (links_find).
!> Prints one line per count: n, then the median and the minimum over the repeats of each, in
!> milliseconds. Run on one rank:
!>     build/tests/bench_particles 1000 10000        (counts; a count is rounded to side^2)
program bench_particles
  use mpi_f08, only: MPI_Init, MPI_Finalize, MPI_Wtime, MPI_COMM_WORLD
  use dkt_kinds, only: wp
  use dkt_domain, only: domain_t, domain_init
  use dkt_choices, only: BB_YU
  use dkt_particles, only: particles_t, particles_init, MOTION_FREE
  use dkt_links, only: links_t, links_init, links_find, links_count
  use dkt_particle_motion, only: particles_move
  implicit none
  integer, parameter :: repeats = 5
  real(wp), parameter :: pitch = 6.0_wp, radius = 2.0_wp
  character(len=32) :: arg
  integer :: a, n

  call MPI_Init()
  do a = 1, command_argument_count()
    call get_command_argument(a, arg)
    read (arg, *) n
    call measure(n)
  end do
  call MPI_Finalize()

contains

  subroutine measure(n_wanted)
    integer, intent(in) :: n_wanted
    type(domain_t) :: dom
    type(particles_t) :: ps
    type(links_t) :: lk
    character(len=:), allocatable :: err
    real(wp), allocatable :: x(:), y(:), zero(:)
    real(wp) :: t_contact(repeats), t_links(repeats), t0
    integer :: side, n, k, rep
    side = max(1, nint(sqrt(real(n_wanted, wp))))
    n = side*side
    allocate (x(n), y(n), zero(n))
    do k = 1, n
      x(k) = pitch*(mod(k - 1, side) + 0.5_wp)
      y(k) = pitch*((k - 1)/side + 0.5_wp)
    end do
    zero = 0.0_wp
    call domain_init(dom, MPI_COMM_WORLD, nint(side*pitch), nint(side*pitch), .false., .false., &
                     1, err)
    if (len(err) > 0) error stop err
    call particles_init(ps, dom, x, y, [(radius, k=1, n)], zero, zero, zero, [(1.01_wp, k=1, n)], &
                        [(MOTION_FREE, k=1, n)], 1.0e-5_wp, 1.0_wp, 1.0_wp, 1.0_wp, 1)
    call links_init(lk, dom, BB_YU, .false., .false.)
    do rep = 1, repeats
      t0 = MPI_Wtime()
      call particles_move(ps, dom, [.true., .true.], .false.)
      t_contact(rep) = 1.0e3_wp*(MPI_Wtime() - t0)
      t0 = MPI_Wtime()
      call links_find(lk, ps, dom)
      t_links(rep) = 1.0e3_wp*(MPI_Wtime() - t0)
    end do
    write (*, '(a, i8, 2(a, f12.3, a, f12.3), a, i9)') 'n', n, '  contact ms', median(t_contact), &
      ' min', minval(t_contact), '  links ms', median(t_links), ' min', minval(t_links), &
      '  links', links_count(lk)
  end subroutine measure

  real(wp) function median(t)
    real(wp), intent(in) :: t(:)
    real(wp) :: s(size(t)), v
    integer :: i, j
    s = t
    do i = 2, size(s)
      v = s(i)
      do j = i - 1, 1, -1
        if (s(j) <= v) exit
        s(j + 1) = s(j)
      end do
      s(j + 1) = v
    end do
    median = s((size(s) + 1)/2)
  end function median

end program bench_particles

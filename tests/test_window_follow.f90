!> Unit tests of the moving window's follow loop (src/dkt_window.f90, docs/model.md §5), whose
!> length depends on the particle state:
!>  - a particle below the window's `below` line is followed row by row until it is within one
!>    spacing of it (the shift and the new position are exact);
!>  - a position that is not finite (NaN, -Infinity: a flow gone NaN, or a damaged checkpoint)
!>    moves nothing and returns, where the loop once spun for ever;
!>  - a finite but absurd position (-1e300) moves the window at most ny rows in one call.
!> Each case would hang, not fail, without the bound: ctest's timeout turns that into a failure.
program test_window_follow
  use ieee_arithmetic, only: ieee_value, ieee_quiet_nan, ieee_negative_inf
  use mpi_f08, only: MPI_Init, MPI_Finalize, MPI_COMM_WORLD
  use dkt_kinds, only: wp
  use dkt_check, only: check, finish
  use dkt_domain, only: domain_t, domain_init, domain_free
  use dkt_store, only: lattice_t, lattice_allocate, lattice_free
  use dkt_particles, only: particles_t, particles_init, MOTION_FREE
  use dkt_window, only: window_t, window_init, window_follow
  implicit none
  integer, parameter :: NX = 8, NY = 40
  type(domain_t) :: dom
  type(lattice_t) :: f
  character(len=:), allocatable :: err

  call MPI_Init()
  call domain_init(dom, MPI_COMM_WORLD, NX, NY, .false., .false., 4, err)
  if (len(err) > 0) error stop err
  call lattice_allocate(f, dom%nxp, dom%nyl, .false., .false., .false., half=.false.)

  call follow(5.0_wp, 4, 9.0_wp, 'a particle 5 rows below the line is followed by 4 rows')
  call follow(ieee_value(1.0_wp, ieee_quiet_nan), 0, -1.0_wp, &
              'a NaN position moves nothing and returns')
  call follow(ieee_value(1.0_wp, ieee_negative_inf), 0, -1.0_wp, &
              'a -Infinity position moves nothing and returns')
  call follow(-1.0e300_wp, NY, -1.0_wp, 'an absurd position moves the window at most ny rows')

  call lattice_free(f)
  call domain_free(dom)
  call finish()
  call MPI_Finalize()

contains

  !> One free particle at y0 (lattice units), the window's line at 10 spacings: the window
  !! must move `rows` rows and leave the particle at `y1` (not checked when y1 < 0).
  subroutine follow(y0, rows, y1, name)
    real(wp), intent(in) :: y0, y1
    integer, intent(in) :: rows
    character(len=*), intent(in) :: name
    type(window_t) :: win
    type(particles_t) :: ps
    call window_init(win, 0.0_wp, 10.0_wp, 1.0_wp)
    call particles_init(ps, dom, [4.0_wp], [y0], [1.0_wp], [0.0_wp], [0.0_wp], [0.0_wp], &
                        [1.01_wp], [MOTION_FREE], 0.0_wp, 1.0_wp, 1.0_wp, 1.0_wp, 1)
    call window_follow(win, dom, ps, f)
    if (y1 >= 0.0_wp) then
      call check(name, win%shift == rows .and. ps%p%y(1) == y1, real(win%shift, wp))
    else
      call check(name, win%shift == rows, real(win%shift, wp))
    end if
  end subroutine follow

end program test_window_follow

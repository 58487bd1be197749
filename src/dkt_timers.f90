!> Where a run's time goes: wall-clock seconds of the time loop summed per part (the flow
!! sweep, the boundary links, the particles, the window, guards, output, checkpoints), for the
!! `time per part` line after the performance line (docs/performance.md). Each part is a
!! start/stop pair around the calls that make it up; a pair costs two MPI_Wtime calls, far
!! below a step's time, and reads nothing of the state, so it changes no result. Within the
!! parts, the time a rank waits for others (a halo that has not arrived, a neighbour's particle
!! message, a reduction) is summed apart too (wait_start, wait_stop), so that a rank's busy time
!! is the loop's less its waits: the balance of the slabs.
module dkt_timers
  use dkt_kinds, only: wp
  use mpi_f08, only: MPI_Wtime
  implicit none
  private
  public :: timer_start, timer_stop, timer_reset, timer_seconds, timer_name, N_PARTS, &
            wait_start, wait_stop, wait_seconds, &
            PART_FLOW, PART_LINKS, PART_PARTICLES, PART_WINDOW, PART_GUARDS, PART_OUTPUT, &
            PART_CHECKPOINTS

  ! the parts, in the order the line prints them
  integer, parameter :: PART_FLOW = 1 !! halo exchange, ghosts, stream-collide, open ends
  integer, parameter :: PART_LINKS = 2 !! bounce-back (E6), interior nodes, link search
  integer, parameter :: PART_PARTICLES = 3 !! force sums (E7), motion (E8–E11), the pair's sample
  integer, parameter :: PART_WINDOW = 4 !! the window's shift and growth
  integer, parameter :: PART_GUARDS = 5 !! the guards: the fluid's, the particles' places and speeds
  integer, parameter :: PART_OUTPUT = 6 !! series, fields, tables on their schedule; progress line
  integer, parameter :: PART_CHECKPOINTS = 7 !! checkpoints, the clock and signal checks
  integer, parameter :: N_PARTS = 7

  real(wp), save :: total(N_PARTS) = 0.0_wp
  real(wp), save :: since(N_PARTS) = 0.0_wp
  real(wp), save :: waited = 0.0_wp, wait_since = 0.0_wp

contains

  !> Start timing one part.
  subroutine timer_start(part)
    integer, intent(in) :: part
    since(part) = MPI_Wtime()
  end subroutine timer_start

  !> Add the time since timer_start(part) to the part's sum.
  subroutine timer_stop(part)
    integer, intent(in) :: part
    total(part) = total(part) + (MPI_Wtime() - since(part))
  end subroutine timer_stop

  !> All sums to zero (at the start of a time loop).
  subroutine timer_reset()
    total = 0.0_wp
    waited = 0.0_wp
  end subroutine timer_reset

  !> Start timing a wait for other ranks.
  subroutine wait_start()
    wait_since = MPI_Wtime()
  end subroutine wait_start

  !> Add the time since wait_start to the waits.
  subroutine wait_stop()
    waited = waited + (MPI_Wtime() - wait_since)
  end subroutine wait_stop

  !> This rank's seconds waiting for other ranks since timer_reset.
  real(wp) function wait_seconds()
    wait_seconds = waited
  end function wait_seconds

  !> This rank's seconds in each part since timer_reset.
  function timer_seconds() result(s)
    real(wp) :: s(N_PARTS)
    s = total
  end function timer_seconds

  !> The name of a part, as the log prints it.
  function timer_name(part) result(name)
    integer, intent(in) :: part
    character(len=:), allocatable :: name
    select case (part)
    case (PART_FLOW)
      name = 'flow'
    case (PART_LINKS)
      name = 'links'
    case (PART_PARTICLES)
      name = 'particles'
    case (PART_WINDOW)
      name = 'window'
    case (PART_GUARDS)
      name = 'guards'
    case (PART_OUTPUT)
      name = 'output'
    case default
      name = 'checkpoints'
    end select
  end function timer_name

end module dkt_timers

!> Why the time loop ends: one decision a step (`stop_t`), which the step, the guards and the
!! checkpoint policy fill in that order, and which the loop reads in one place. Its kind then
!! says how the run ends (docs/running.md, "When a run stops"): the run file's `stop_reason`,
!! the messages and the exit status.
module dkt_stop
  implicit none
  private
  public :: stop_t, stop_after_step, stop_set, stop_failed, stop_last, STOP_NONE, &
            STOP_FINISHED, STOP_WINDOW, STOP_PARTICLE, STOP_GUARD, STOP_INTERRUPTED

  ! the kinds of stop; a failure (particle, guard) ends the step at once, the others after it
  integer, parameter :: STOP_NONE = 0 !! the loop goes on
  integer, parameter :: STOP_FINISHED = 1 !! the last step of run.steps
  integer, parameter :: STOP_WINDOW = 2 !! a particle near the upper end of a window that
  !! cannot grow (further): the run ends with its output, as a finished one
  integer, parameter :: STOP_PARTICLE = 3 !! a particle out of place (left the lattice, a
  !! prescribed one at a wall or in another body)
  integer, parameter :: STOP_GUARD = 4 !! a guard: a non-finite value, the Mach limit, a
  !! particle faster than run.particle_speed_limit
  integer, parameter :: STOP_INTERRUPTED = 5 !! a signal or run.wall_limit, after the
  !! checkpoint the run resumes from

  !> The decision of one step: whether the loop ends after it, and why
  type :: stop_t
    integer :: kind = STOP_NONE
    logical :: now = .false. !! the loop ends with this step (any kind but STOP_NONE)
    character(len=:), allocatable :: message !! what a failure or a window's end says
  end type stop_t

contains

  !> What the step found: a particle out of place (`placed`), one too fast (`fast`), a window
  !! that cannot follow the particles (`escaped`), each '' when none, and whether the step was
  !! the last. A particle out of place is named before one too fast, and both before the end
  !! of the window or of the run: the output of a failed step is the failure's. The fluid
  !! guards, which run after every step that ends the loop, may still override it (stop_set).
  pure subroutine stop_after_step(stop, placed, fast, escaped, last_step)
    type(stop_t), intent(inout) :: stop
    character(len=*), intent(in) :: placed, fast, escaped
    logical, intent(in) :: last_step
    if (len(placed) > 0) then
      call stop_set(stop, STOP_PARTICLE, placed)
    else if (len(fast) > 0) then
      call stop_set(stop, STOP_GUARD, fast)
    else if (len(escaped) > 0) then
      call stop_set(stop, STOP_WINDOW, escaped)
    else if (last_step) then
      call stop_set(stop, STOP_FINISHED)
    else
      call stop_set(stop, STOP_NONE)
    end if
  end subroutine stop_after_step

  !> The stop of this step is of `kind`, with `message` ('' when not given); it replaces
  !! whatever the step had decided before.
  pure subroutine stop_set(stop, kind, message)
    type(stop_t), intent(inout) :: stop
    integer, intent(in) :: kind
    character(len=*), intent(in), optional :: message
    stop%kind = kind
    stop%now = kind /= STOP_NONE
    stop%message = ''
    if (present(message)) stop%message = message
  end subroutine stop_set

  !> Whether the step failed (a particle out of place or a guard): nothing more of the step
  !! runs; the run's end writes its state and stops every rank with the message.
  pure logical function stop_failed(stop)
    type(stop_t), intent(in) :: stop
    stop_failed = stop%kind == STOP_PARTICLE .or. stop%kind == STOP_GUARD
  end function stop_failed

  !> Whether the step is the run's last to be output as a finished run's (the last step, or
  !! the window's end): the scheduled output and the progress line leave it to the run's end.
  pure logical function stop_last(stop)
    type(stop_t), intent(in) :: stop
    stop_last = stop%kind == STOP_FINISHED .or. stop%kind == STOP_WINDOW
  end function stop_last

end module dkt_stop

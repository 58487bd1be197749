!> The signals that ask a run to stop: what batch systems send before a job's time limit
!> (SIGTERM, SIGUSR1, SIGUSR2, SIGXCPU), Ctrl-C (SIGINT), a closed terminal (SIGHUP) and a
!> timer (SIGALRM). The handler only notes the signal; the time loop asks at each step boundary,
!> writes a checkpoint and stops cleanly. SIGPIPE is ignored: a closed standard output (a pipe
!> whose reader has gone) ends the console copy of the log, not the run (dkt_log). The signal
!> numbers are Linux's, where clusters run.
module dkt_signals
  use iso_c_binding, only: c_int, c_funptr, c_funloc, c_intptr_t, c_null_funptr
  implicit none
  private
  public :: signals_install, signals_release, signal_mask, signal_name

  integer(c_int), parameter :: SIGHUP = 1, SIGINT = 2, SIGUSR1 = 10, SIGUSR2 = 12, &
                               SIGPIPE = 13, SIGALRM = 14, SIGTERM = 15, SIGXCPU = 24
  !> the signals that stop a run, in the order their names are preferred in the log
  integer(c_int), parameter :: STOPPING(*) = [SIGTERM, SIGINT, SIGHUP, SIGUSR1, SIGUSR2, &
                                              SIGXCPU, SIGALRM]
  character(len=*), parameter :: NAMES(*) = ['SIGTERM', 'SIGINT ', 'SIGHUP ', 'SIGUSR1', &
                                             'SIGUSR2', 'SIGXCPU', 'SIGALRM']
  !> seen(s) /= 0 once signal s has been caught: one store per signal, safe in a handler
  integer(c_int), volatile, save :: seen(SIGXCPU) = 0

  interface
    function c_signal(signum, handler) bind(c, name='signal') result(previous)
      import :: c_int, c_funptr
      integer(c_int), value :: signum
      type(c_funptr), value :: handler
      type(c_funptr) :: previous
    end function c_signal
    function c_raise(signum) bind(c, name='raise') result(status)
      import :: c_int
      integer(c_int), value :: signum
      integer(c_int) :: status
    end function c_raise
  end interface

contains

  !> From now on the stopping signals are noted instead of ending the process, and SIGPIPE is
  !! ignored (a write to a closed pipe then fails with an error the writer handles).
  subroutine signals_install()
    type(c_funptr) :: previous
    integer :: k
    do k = 1, size(STOPPING)
      previous = c_signal(STOPPING(k), c_funloc(on_signal))
    end do
    ! SIG_IGN is the handler address 1 in <signal.h>
    previous = c_signal(SIGPIPE, transfer(1_c_intptr_t, previous))
  end subroutine signals_install

  !> For a process with nothing to keep (--check, --print-defaults): the stopping signals end
  !! it at once again, as they do by default, and one caught already ends it now. A long
  !! check stays interruptible by Ctrl-C.
  subroutine signals_release()
    type(c_funptr) :: previous
    integer :: k
    integer(c_int) :: status
    do k = 1, size(STOPPING)
      ! SIG_DFL is the handler address 0 in <signal.h>
      previous = c_signal(STOPPING(k), c_null_funptr)
    end do
    do k = 1, size(STOPPING)
      if (seen(STOPPING(k)) /= 0) status = c_raise(STOPPING(k))
    end do
  end subroutine signals_release

  !> The stopping signals caught since the start: bit s is set for signal s (1 <= s <= 24), so
  !! that the ranks can combine theirs with a bitwise or.
  integer function signal_mask()
    integer :: s
    signal_mask = 0
    do s = 1, size(seen)
      if (seen(s) /= 0) signal_mask = ibset(signal_mask, s)
    end do
  end function signal_mask

  !> The name of a signal in `mask` (signal_mask, or several ranks' masks or-ed), SIGTERM
  !! first; 'a signal' when it holds none of the stopping signals.
  function signal_name(mask) result(name)
    integer, intent(in) :: mask
    character(len=:), allocatable :: name
    integer :: k
    name = 'a signal'
    do k = 1, size(STOPPING)
      if (btest(mask, STOPPING(k))) then
        name = trim(NAMES(k))
        return
      end if
    end do
  end function signal_name

  subroutine on_signal(signum) bind(c)
    integer(c_int), value :: signum
    if (signum >= 1 .and. signum <= size(seen)) seen(signum) = 1
  end subroutine on_signal

end module dkt_signals

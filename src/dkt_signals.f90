!> The signals a batch system sends before a job's time limit (SIGTERM, SIGUSR1): the handler
!> only notes the signal; the time loop asks at each step boundary, writes a checkpoint and
!> stops cleanly. The signal numbers are Linux's, where clusters run.
module dkt_signals
  use iso_c_binding, only: c_int, c_funptr, c_funloc
  implicit none
  private
  public :: signals_install, signal_caught, SIGTERM, SIGUSR1

  integer(c_int), parameter :: SIGTERM = 15, SIGUSR1 = 10
  !> the last signal caught, 0 if none
  integer(c_int), volatile, save :: caught = 0

  interface
    function c_signal(signum, handler) bind(c, name='signal') result(previous)
      import :: c_int, c_funptr
      integer(c_int), value :: signum
      type(c_funptr), value :: handler
      type(c_funptr) :: previous
    end function c_signal
  end interface

contains

  !> From now on SIGTERM and SIGUSR1 are noted instead of ending the process.
  subroutine signals_install()
    type(c_funptr) :: previous
    previous = c_signal(SIGTERM, c_funloc(on_signal))
    previous = c_signal(SIGUSR1, c_funloc(on_signal))
  end subroutine signals_install

  !> The signal caught since the start (SIGTERM or SIGUSR1), 0 if none.
  integer function signal_caught()
    signal_caught = caught
  end function signal_caught

  subroutine on_signal(signum) bind(c)
    integer(c_int), value :: signum
    caught = signum
  end subroutine on_signal

end module dkt_signals

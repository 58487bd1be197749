!> The one error routine of dktlbm. Every stop for bad input or a failed guard goes through here,
!> so that all ranks end, the exit status is non-zero, and the message is printed once.
module dkt_errors
  use iso_fortran_env, only: error_unit, output_unit
  use mpi_f08, only: MPI_COMM_WORLD, MPI_Comm_rank, MPI_Abort, MPI_Finalize, MPI_Initialized, &
                     MPI_Finalized
  use dkt_log, only: log_record, log_close
  use dkt_text, only: printable, itoa
  implicit none
  private
  public :: fatal_all, fatal_local, internal_error, warn, EXIT_INPUT, EXIT_RUNTIME

  integer, parameter :: EXIT_INPUT = 2   !! exit status for bad input
  !> exit status for a run stopped by a guard or a failed write
  integer, parameter :: EXIT_RUNTIME = 3

contains

  !> Stop every rank for an error that all ranks detected together (input validation is
  !! deterministic on every rank): rank 0 prints, all ranks finalise MPI and exit non-zero.
  !! Input quoted in `text` is shown with its non-printing bytes escaped (printable); the line
  !! breaks of `text` stay line breaks.
  subroutine fatal_all(text, code)
    character(len=*), intent(in) :: text  !! what is wrong and what to change
    integer, intent(in), optional :: code !! exit status (default EXIT_INPUT)
    integer :: status
    logical :: running
    character(len=:), allocatable :: msg
    msg = printable_lines(text)
    status = EXIT_INPUT
    if (present(code)) status = code
    if (this_rank(running) == 0) call to_stderr('dktlbm: error: '//msg)
    if (running) call log_record('error: '//msg)
    call log_close()
    if (running) call MPI_Finalize()
    stop status, quiet = .true.
  end subroutine fatal_all

  !> Stop every rank for an error that one rank saw alone (a failed HDF5 call or write on it):
  !! that rank prints with its number and aborts the whole job, so no rank waits forever. The
  !! output is not closed then; errors all ranks see stop through fatal_all after closing it.
  subroutine fatal_local(text, code)
    character(len=*), intent(in) :: text
    integer, intent(in), optional :: code
    integer :: status
    logical :: running
    character(len=:), allocatable :: msg
    msg = printable_lines(text)
    status = EXIT_RUNTIME
    if (present(code)) status = code
    call to_stderr('dktlbm: error [rank '//itoa(this_rank(running))//']: '//msg)
    ! the log file is rank 0's; the other ranks' errors are on standard error only
    if (running) call log_record('error: '//msg)
    call log_close()
    if (running) call MPI_Abort(MPI_COMM_WORLD, status)
    stop status, quiet = .true.
  end subroutine fatal_local

  !> Stop the run on a value the program itself should never have made (a choice code that no
  !! case handles): the input was checked, so this is a defect, never a fallback.
  subroutine internal_error(what)
    character(len=*), intent(in) :: what !! which value, and where
    call fatal_local('internal error: '//what)
  end subroutine internal_error

  !> A warning, printed once by rank 0; the run goes on.
  subroutine warn(msg)
    character(len=*), intent(in) :: msg
    logical :: running
    if (this_rank(running) == 0) call to_stderr('dktlbm: warning: '//msg)
    if (running) call log_record('warning: '//msg)
  end subroutine warn

  !> One message on standard error, after what standard output holds so far. A console that
  !! cannot be written (a closed pipe) is passed over: the log file has the message.
  subroutine to_stderr(line)
    character(len=*), intent(in) :: line
    integer :: ios
    flush (output_unit, iostat=ios)
    write (error_unit, '(a)', iostat=ios) line
    flush (error_unit, iostat=ios)
  end subroutine to_stderr

  !> `text` with the non-printing bytes of each line escaped, the line breaks kept.
  function printable_lines(text) result(msg)
    character(len=*), intent(in) :: text
    character(len=:), allocatable :: msg
    integer :: a, b
    msg = ''
    a = 1
    do
      b = index(text(a:), new_line('a'))
      if (b == 0) exit
      msg = msg//printable(text(a:a + b - 2))//new_line('a')
      a = a + b
    end do
    msg = msg//printable(text(a:))
  end function printable_lines

  !> This process's rank in MPI_COMM_WORLD (0 when MPI is not running); running tells whether
  !! MPI is initialised and not yet finalised.
  integer function this_rank(running)
    logical, intent(out) :: running
    logical :: up, down
    call MPI_Initialized(up)
    call MPI_Finalized(down)
    running = up .and. .not. down
    this_rank = 0
    if (running) call MPI_Comm_rank(MPI_COMM_WORLD, this_rank)
  end function this_rank

end module dkt_errors

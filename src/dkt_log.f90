!> The run log: lines from rank 0 go to standard output and, once the output directory is
!> known, also into <output.dir>/<name>.log (lines written before that are replayed there).
!> Warnings and errors go to standard error (dkt_errors) and, through log_record, into the log
!> file too, so that the log alone tells why a run stopped. A console that cannot be written
!> (closed standard output or error) never stops a run: the log file keeps every line.
module dkt_log
  use iso_fortran_env, only: output_unit
  use mpi_f08, only: MPI_COMM_WORLD, MPI_Comm_rank, MPI_Initialized, MPI_Finalized
  implicit none
  private
  public :: log_line, log_record, log_open, log_close

  integer, save :: log_unit = -1
  !> whether the log file is open (newunit= gives negative unit numbers, so the unit cannot tell)
  logical, save :: log_is_open = .false.
  character(len=:), allocatable, save :: pending   !! lines logged before log_open
  logical, save :: to_stdout = .true.

contains

  logical function is_root()
    integer :: rank
    call MPI_Comm_rank(MPI_COMM_WORLD, rank)
    is_root = rank == 0
  end function is_root

  !> Print one line on rank 0 (and keep it for the log file). A standard output that cannot
  !! be written (a pipe whose reader has gone: `dktlbm ... | head`) ends the console copy; the
  !! run and its log file go on.
  subroutine log_line(msg)
    character(len=*), intent(in) :: msg
    integer :: ios
    if (.not. is_root()) return
    if (to_stdout) then
      write (output_unit, '(a)', iostat=ios) msg
      if (ios == 0) flush (output_unit, iostat=ios)
      if (ios /= 0) to_stdout = .false.
    end if
    call to_file(msg)
  end subroutine log_line

  !> Keep one line (rank 0's) for the log file only, not standard output: the warnings and
  !! errors that dkt_errors prints to standard error.
  subroutine log_record(msg)
    character(len=*), intent(in) :: msg
    logical :: up, down
    ! errors can come before MPI_Init or after MPI_Finalize; no log file is open then
    call MPI_Initialized(up)
    call MPI_Finalized(down)
    if (.not. up .or. down) return
    if (.not. is_root()) return
    call to_file(msg)
  end subroutine log_record

  !> One line into the log file, or kept until it is opened.
  subroutine to_file(msg)
    character(len=*), intent(in) :: msg
    if (log_is_open) then
      write (log_unit, '(a)') msg
      flush (log_unit)
    else
      if (.not. allocated(pending)) pending = ''
      pending = pending//msg//new_line('a')
    end if
  end subroutine to_file

  !> Open the log file on rank 0 and write the lines logged so far; `append` (a resumed run)
  !! continues an existing log. err is '' on success.
  subroutine log_open(path, err, append)
    character(len=*), intent(in) :: path
    character(len=:), allocatable, intent(out) :: err
    logical, intent(in), optional :: append
    integer :: ios
    character(len=256) :: iomsg
    err = ''
    ios = 1
    if (.not. is_root()) return
    if (present(append)) then
      if (append) then
        open (newunit=log_unit, file=path, status='unknown', position='append', &
              action='write', iostat=ios, iomsg=iomsg)
      end if
    end if
    if (.not. (present(append) .and. ios == 0)) &
      open (newunit=log_unit, file=path, status='replace', action='write', iostat=ios, &
            iomsg=iomsg)
    if (ios /= 0) then
      err = 'cannot write the log file '''//path//''': '//trim(iomsg)
      return
    end if
    log_is_open = .true.
    if (allocated(pending)) then
      write (log_unit, '(a)', advance='no') pending
      flush (log_unit)
      deallocate (pending)
    end if
  end subroutine log_open

  subroutine log_close()
    if (log_is_open) close (log_unit)
    log_is_open = .false.
  end subroutine log_close

end module dkt_log

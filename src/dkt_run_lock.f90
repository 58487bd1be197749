!> A run's hold on its output directory: while a run writes into output.dir, rank 0 holds
!> <name>.lock there (an flock, dkt_filesystem lock_take, which the system drops when the
!> process ends, however it ends), and a second run of the scene into that directory is refused
!> before it changes anything, with output.overwrite and on --restart too (docs/running.md).
module dkt_run_lock
  use mpi_f08, only: MPI_Bcast, MPI_LOGICAL, MPI_Get_processor_name, MPI_MAX_PROCESSOR_NAME
  use dkt_errors, only: fatal_all, fatal_local
  use dkt_filesystem, only: lock_take, lock_held, process_id
  use dkt_text, only: itoa
  use dkt_run_state, only: simulation_t
  implicit none
  private
  public :: run_lock_check, run_lock_take

contains

  !> Hold output.dir for this scene while the run writes there (rank 0 takes <name>.lock,
  !! dkt_filesystem lock_take), so that no second run writes the same files, not even with
  !! output.overwrite or --restart. Taken once the run's other checks have passed: a refused
  !! run leaves the directory as it was. The system drops the lock when the process ends,
  !! however it ends.
  subroutine run_lock_take(sim, fd)
    type(simulation_t), intent(in) :: sim
    integer, intent(out) :: fd !! rank 0's descriptor of the lock (lock_release), else -1
    character(len=MPI_MAX_PROCESSOR_NAME) :: host
    character(len=:), allocatable :: holder, err
    integer :: n
    logical :: ok
    ok = .true.
    fd = -1
    if (sim%dom%rank == 0) then
      call MPI_Get_processor_name(host, n)
      call lock_take(lock_path(sim), 'dktlbm pid '//itoa(process_id())//' on host '// &
                     host(1:n)//', scene '//trim(sim%cfg%file), fd, holder, err)
      if (len(err) > 0) call fatal_local(trim(sim%cfg%file)//': output.dir = '''// &
                                         sim%cfg%output_dir//''': '//err)
      ok = fd >= 0
    end if
    call MPI_Bcast(ok, 1, MPI_LOGICAL, 0, sim%dom%comm)
    if (ok) return
    ! (another run took it since run_lock_check looked)
    if (.not. allocated(holder)) allocate (character(len=0) :: holder)
    call refuse_live_run(sim, holder)
  end subroutine run_lock_take

  !> Stop every rank, changing nothing, when a live run holds output.dir for this scene (its
  !! <name>.lock), whatever output.overwrite says and on a restart too.
  subroutine run_lock_check(sim)
    type(simulation_t), intent(in) :: sim
    character(len=:), allocatable :: holder
    logical :: held
    held = .false.
    if (sim%dom%rank == 0) held = lock_held(lock_path(sim), holder)
    call MPI_Bcast(held, 1, MPI_LOGICAL, 0, sim%dom%comm)
    if (.not. held) return
    if (.not. allocated(holder)) allocate (character(len=0) :: holder)
    call refuse_live_run(sim, holder)
  end subroutine run_lock_check

  function lock_path(sim) result(path)
    type(simulation_t), intent(in) :: sim
    character(len=:), allocatable :: path
    path = sim%cfg%output_dir//'/'//sim%cfg%name//'.lock'
  end function lock_path

  subroutine refuse_live_run(sim, holder)
    type(simulation_t), intent(in) :: sim
    character(len=*), intent(in) :: holder !! what the holder wrote (rank 0), '' if unknown
    character(len=:), allocatable :: who
    who = holder
    if (len(who) == 0) who = 'a process that has not said which'
    call fatal_all(trim(sim%cfg%file)//': output.dir = '''//sim%cfg%output_dir//''' is held '// &
                   'by a live run of scene '''//sim%cfg%name//''' ('//who//', '// &
                   lock_path(sim)//'): a second run would overwrite its files, so nothing '// &
                   'there was changed. Wait until that run ends, stop it, or choose another '// &
                   'output.dir')
  end subroutine refuse_live_run

end module dkt_run_lock

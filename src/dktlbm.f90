!> dktlbm: particles settling in a 2-D channel, D2Q9 MRT lattice Boltzmann on MPI slabs.
!> The driver: read and check the input, set up, run, finish.
program dktlbm
  use iso_fortran_env, only: output_unit
  use mpi_f08, only: MPI_Init, MPI_Finalize, MPI_COMM_WORLD, MPI_Comm_rank, MPI_Bcast, &
                     MPI_INTEGER, MPI_CHARACTER, MPI_Barrier
  use dkt_signals, only: signals_install, signals_release
  use dkt_errors, only: fatal_all, warn
  use dkt_config, only: cli_t, config_t, lattice_params_t, parse_command_line, read_text_file, &
                        config_load, config_to_namelist, print_help, &
                        config_check_text
  use dkt_run, only: run_t, run_setup, run_execute, run_finish
  use dkt_config_restart, only: restart_changes_problem, restart_input_check
  use dkt_version, only: dkt_version_string, dkt_git_revision
  implicit none

  type(cli_t) :: cli
  type(config_t) :: cfg
  type(lattice_params_t) :: lp
  type(run_t), asynchronous :: run
  character(len=:), allocatable :: err, text, warnings
  integer :: rank, status

  ! the stopping signals (SIGTERM, SIGINT, SIGHUP, SIGUSR1, ...) are noted from the very start,
  ! so that a signal sent while the run is still setting up stops it cleanly at its first steps
  ! instead of killing it, and SIGPIPE is ignored (a closed standard output is not fatal)
  call signals_install()
  call MPI_Init()
  call MPI_Comm_rank(MPI_COMM_WORLD, rank)
  call announce_ready()

  call parse_command_line(cli, err)
  if (len(err) > 0) call fatal_all(err)
  ! a check writes nothing to keep: Ctrl-C ends it at once, as it ends any command
  if (cli%check .or. cli%print_defaults) call signals_release()
  if (cli%help .or. cli%version .or. (cli%print_defaults .and. len(cli%nml_file) == 0)) then
    if (rank == 0) call print_info(cli)
    call MPI_Finalize()
    stop
  end if

  call read_input(cli%nml_file, text)
  call config_check_text(text, cli%nml_file, err)
  if (len(err) > 0) call fatal_all(err)
  ! validates the input (each key, then the rules that join keys) once and derives the lattice
  call config_load(cfg, text, cli%nml_file, cli%overrides, err, warnings, lp)
  if (len(err) == 0) err = restart_changes_problem(cfg)
  if (len(err) > 0) call fatal_all(err)
  if (cli%print_defaults) then
    ! the file's values with the --set options applied, as a namelist that reads back
    if (rank == 0) write (output_unit, '(a)', advance='no', iostat=status) cfg%given
    call MPI_Finalize()
    stop
  end if
  call warn_lines(warnings)

  ! --check sets up all but the lattices (the memory check included), reports and refuses
  ! what the run would refuse
  call run_setup(run, cfg, lp, MPI_COMM_WORLD, cli%restart, cli%check, restart_input_check)
  if (.not. cli%check) call run_execute(run)
  call run_finish(run)
  call MPI_Finalize()

contains

  !> When the environment names a file in DKTLBM_READY_FILE, rank 0 creates it once every rank
  !! notes the signals: a batch script that holds a signal until then loses none.
  subroutine announce_ready()
    integer :: n, status, unit
    character(len=:), allocatable :: path
    call get_environment_variable('DKTLBM_READY_FILE', length=n, status=status)
    if (status /= 0 .or. n == 0) return
    call MPI_Barrier(MPI_COMM_WORLD)
    if (rank /= 0) return
    allocate (character(len=n) :: path)
    call get_environment_variable('DKTLBM_READY_FILE', path)
    open (newunit=unit, file=path, status='replace', action='write', iostat=status)
    if (status == 0) close (unit)
  end subroutine announce_ready

  !> Rank 0 reads the namelist file and sends its text to every rank, so all ranks validate
  !! the same input and stop together on an error.
  subroutine read_input(path, text)
    character(len=*), intent(in) :: path
    character(len=:), allocatable, intent(out) :: text
    character(len=:), allocatable :: err
    integer :: n
    n = -1
    if (rank == 0) then
      call read_text_file(path, text, err)
      if (len(err) == 0) n = len(text)
    end if
    call MPI_Bcast(n, 1, MPI_INTEGER, 0, MPI_COMM_WORLD)
    ! only rank 0 read the file and prints the message; the others stop with it
    if (n < 0 .and. rank == 0) call fatal_all(err)
    if (n < 0) call fatal_all('')
    if (rank /= 0) allocate (character(len=n) :: text)
    if (n > 0) call MPI_Bcast(text, n, MPI_CHARACTER, 0, MPI_COMM_WORLD)
  end subroutine read_input

  !> Each line of a newline-separated list of warnings, through the one warning routine.
  subroutine warn_lines(lines)
    character(len=*), intent(in) :: lines
    integer :: a, b
    a = 1
    do while (a <= len(lines))
      b = index(lines(a:), new_line('a'))
      if (b == 0) then
        b = len(lines) + 1
      else
        b = a + b - 1
      end if
      if (b > a) call warn(lines(a:b - 1))
      a = b + 1
    end do
  end subroutine warn_lines

  subroutine print_info(cli)
    type(cli_t), intent(in) :: cli
    type(config_t) :: defaults
    character(len=:), allocatable :: nml
    integer :: status !! a closed standard output (`| head`) is not an error here
    if (cli%help) then
      call print_help(output_unit)
    else if (cli%version) then
      write (output_unit, '(a)', iostat=status) 'dktlbm '//dkt_version_string//' ('// &
        dkt_git_revision//')'
    else
      call config_to_namelist(defaults, nml)
      write (output_unit, '(a)', advance='no', iostat=status) nml
    end if
  end subroutine print_info

end program dktlbm

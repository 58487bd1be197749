!> The run's output files: the run file (<name>.h5: /run, fields, /particles, /diagnostics),
!> the pair's CSV file and the log, opened (or continued after a restart) once the input is
!> checked, written on the loop's schedule, completed and closed however the run ends.
module dkt_output
  use mpi_f08, only: MPI_Bcast, MPI_LOGICAL
  use iso_fortran_env, only: compiler_version
  use iso_c_binding, only: c_long
  use dkt_kinds, only: wp, cs2, i8, mpi_wp
  use dkt_errors, only: fatal_all, fatal_local, internal_error, EXIT_RUNTIME
  use dkt_mrt, only: collision_describe
  use dkt_fields, only: macroscopic, vorticity
  use dkt_particles, only: particle_t, particles_gather
  use dkt_links, only: particles_solid_field
  use dkt_suspension, only: suspension_stats, suspension_bins, FRONT_FRACTION
  use dkt_choices, only: MOTION_FREE
  use dkt_diagnostics, only: pair_pattern, pair_gaps, drag_coefficient
  use dkt_window, only: window_offset
  use dkt_io, only: io_t, io_open, io_write_run, io_write_fields, io_close, io_write_series, &
                    io_write_table, io_write_attribute, io_reopen, io_flush, io_set_rows, &
                    io_read_series, io_run_id
  use dkt_log, only: log_line, log_open
  use dkt_filesystem, only: make_directories, remove_file, path_exists, write_marker, &
                            directory_problem, lock_release, space_problem
  use dkt_text, only: itoa, counted
  use dkt_version, only: dkt_version_string, dkt_git_revision, dkt_build_flags
  use dkt_run_state, only: simulation_t
  use dkt_run_lock, only: run_lock_check, run_lock_take
  implicit none
  private
  public :: output_t, output_open, output_check_existing, output_check_dir, output_fields, &
            output_particles, output_pair_report, output_close, output_fail, output_final, &
            output_scheduled, output_mark_finished, output_initial, output_resume, output_free, &
            output_set_stop_reason, output_flush, output_samples, output_run_id, &
            output_reads_lattice

  !> the longest path (characters) of a file the run opens through MPI-IO: Open MPI 4.1.4
  !! aborts ("buffer overflow detected") from 245 on (docs/running.md); a margin below that
  integer, parameter :: MAX_MPIIO_PATH = 240
  !> the longest namelist io_write_run stores as the attribute /run namelist (dkt_io)
  integer, parameter :: NAMELIST_ATTRIBUTE_MAX = 32768
  !> the columns of the pair's CSV file (csv_row)
  character(len=*), parameter :: CSV_HEADER = 't,tstar,dx,dy,dr,dr_star,re_1,re_2,cd_1,'// &
                                 'cd_2,x_1,y_1,x_2,y_2,u_1,v_1,u_2,v_2,'// &
                                 'omega_1,omega_2'

  !> output fields and their units; in a scene with particles also the integer field
  !! `particle` (written by io_write_fields), in this order
  character(len=9), parameter :: field_names(5) = ['rho      ', 'ux       ', 'uy       ', &
                                                   'vorticity', 'pressure ']
  character(len=10), parameter :: field_units(5) = ['g/cm^3    ', 'cm/s      ', 'cm/s      ', &
                                                    '1/s       ', 'g/(cm s^2)']
  !> the /particles series besides t, one column per particle
  character(len=6), parameter :: series_names(8) = ['x     ', 'y     ', 'u     ', 'v     ', &
                                                    'omega ', 'fx    ', 'fy    ', 'torque']
  !> their units: force and torque per unit depth
  character(len=9), parameter :: series_units(8) = ['cm       ', 'cm       ', 'cm/s     ', &
                                                    'cm/s     ', '1/s      ', 'g/s^2    ', &
                                                    'g/s^2    ', 'g cm/s^2 ']

  !> The run's output: the run file and the pair's CSV file, what of them is written, and
  !! why the run ended. Owned by this module (its components are private): the loop and the
  !! checkpoints hand it in.
  type :: output_t
    private
    type(io_t) :: io
    logical :: file_open = .false.  !! the run file is open
    integer :: csv_unit = 0         !! the diagnostics CSV file (rank 0, when the pair is on)
    logical :: csv_open = .false.
    integer :: samples = 0          !! samples of the /particles series written
    integer :: fields_step = -1     !! the step of the last field snapshot written
    integer :: series_step = -1     !! the step of the last /particles sample written
    logical :: reported = .false.   !! the pair's pattern and episodes are written
    !> why the run ended, stored as /run stop_reason when the output is closed: 'finished',
    !! 'window_escape', 'signal', 'wall_limit', 'guard: <message>' or 'error: <message>'
    character(len=:), allocatable :: stop_reason
    logical :: resumed = .false.    !! the output continues that of a run resumed from a checkpoint
    character(len=:), allocatable :: restart_from !! the checkpoint it resumed from
    !> the changes of the input run.restart_changes allowed on resuming, for the run file:
    !! 'group.key old -> new; ...', '' if none
    character(len=:), allocatable :: restart_changes
    !> the run file's identity (/run run_id), which every checkpoint of the run carries: a
    !! restart refuses a checkpoint of another run's file
    real(wp) :: run_id = 0.0_wp
    !> rank 0's descriptor of <name>.lock in output.dir while the run writes there, else -1
    integer :: lock_fd = -1
  end type output_t

contains

  !> Continue the output of the run that wrote the checkpoint `path` after `samples` samples
  !! of the /particles series, recording the input changes `changes` when the output opens.
  subroutine output_resume(out, path, samples, changes)
    type(output_t), intent(inout) :: out
    character(len=*), intent(in) :: path, changes
    integer, intent(in) :: samples
    out%resumed = .true.
    out%restart_from = path
    out%samples = samples
    out%restart_changes = changes
  end subroutine output_resume

  !> The output at step 0 of a run that does not resume: the fields (when they are written
  !! during the run) and the first particle sample.
  subroutine output_initial(out, sim)
    type(output_t), intent(inout) :: out
    type(simulation_t), intent(in) :: sim
    if (out%resumed) return
    if (sim%lp%field_every > 0) call output_fields(out, sim, 0)
    if (sim%particles_on) call output_particles(out, sim, 0)
  end subroutine output_initial

  !> Record why the run ends ('finished', 'signal', 'guard: <message>', ...), stored as /run
  !! stop_reason when the output is closed.
  subroutine output_set_stop_reason(out, reason)
    type(output_t), intent(inout) :: out
    character(len=*), intent(in) :: reason
    out%stop_reason = reason
  end subroutine output_set_stop_reason

  !> Write the samples held in memory (dkt_io keeps them between flushes) to the open run file.
  subroutine output_flush(out)
    type(output_t), intent(inout) :: out
    if (out%file_open) call io_flush(out%io)
  end subroutine output_flush

  !> The samples of the /particles series written so far (a resumed run counts those of the
  !! run it continues).
  pure integer function output_samples(out)
    type(output_t), intent(in) :: out
    output_samples = out%samples
  end function output_samples

  !> The run file's identity (/run run_id): a whole number in [1, 2^52], drawn when the file is
  !! made; checkpoints carry it (dkt_checkpoint_policy).
  pure real(wp) function output_run_id(out)
    type(output_t), intent(in) :: out
    output_run_id = out%run_id
  end function output_run_id

  !> A new identity for a run file, the same on every rank (rank 0 draws it from the clock of
  !! the day, to the millisecond, and the system clock's count): two runs started apart get
  !! different ones.
  subroutine new_run_id(out, sim)
    type(output_t), intent(inout) :: out
    type(simulation_t), intent(in) :: sim
    integer :: v(8)
    integer(i8) :: count, h
    call date_and_time(values=v)
    call system_clock(count)
    ! the milliseconds since the year 0 (about 2^56) and the count, each hashed in 31 bits
    ! (no product overflows 63 bits), into 52: an id is a whole number, exact in 8 bytes
    h = int(v(1), i8)*372_i8 + v(2)*31_i8 + v(3)
    h = ((h*24_i8 + v(5))*60_i8 + v(6))*60_i8 + v(7)
    h = h*1000_i8 + v(8)
    h = ieor(modulo(h, 2_i8**31)*2654435761_i8, modulo(count, 2_i8**31)*40503_i8)
    out%run_id = real(modulo(h, 2_i8**52), wp) + 1.0_wp
    call MPI_Bcast(out%run_id, 1, mpi_wp, 0, sim%dom%comm)
    call write_quantity(out%io, '/run', 'run_id', out%run_id, '1')
  end subroutine new_run_id

  !> Close whatever of the output is still open, without writing to it.
  subroutine output_free(out)
    type(output_t), intent(inout) :: out
    if (out%file_open) call io_close(out%io)
    out%file_open = .false.
    if (out%csv_open) close (out%csv_unit)
    out%csv_open = .false.
    call lock_release(out%lock_fd)
  end subroutine output_free

  !> Create the output directory and file, and store the run's metadata. Called only after
  !! every input check passed, so a bad input writes nothing.
  subroutine output_open(out, sim)
    type(output_t), intent(inout) :: out
    type(simulation_t), intent(in) :: sim
    character(len=:), allocatable :: dir, err, nml
    character(len=256) :: msg
    integer :: ios
    character(len=64) :: pnames(9)
    real(wp) :: pvalues(9), s(0:8)
    logical :: ok

    out%stop_reason = 'running'
    dir = sim%cfg%output_dir
    err = ''
    if (sim%dom%rank == 0) call make_directories(dir, err)
    ok = len(err) == 0
    call MPI_Bcast(ok, 1, MPI_LOGICAL, 0, sim%dom%comm)
    ! only rank 0 knows the reason; it is the rank that prints
    if (.not. ok) call fatal_all(trim(sim%cfg%file)//': output.dir = '''//dir//''': '// &
                                 err//'; choose a writable output.dir')
    ! a live run's directory is refused before anything else is said or changed
    call run_lock_check(sim)
    if (out%resumed) then
      ! the output of the run that wrote the checkpoint continues, cut back to its step
      call io_reopen(out%io, dir, sim%cfg%name, sim%dom%comm, sim%lp%nx, sim%dom%ny, &
                     sim%dom%y0, sim%dom%nyl, sim%lp%dx, sim%step, out%samples, &
                     [character(len=11) :: 'particles', 'diagnostics', 'suspension'], &
                     [sim%particles_on, sim%pair_on, suspension_on(sim)], &
                     sim%lp%field_every == 0 .or. mod(sim%step, max(1, sim%lp%field_every)) /= 0, &
                     [character(len=9) :: field_names, 'particle'], err)
      if (len(err) > 0) call fatal_all(trim(sim%cfg%file)//': --restart '// &
                                       out%restart_from//': '//err)
      call run_lock_take(sim, out%lock_fd)
      out%io%compress = sim%cfg%output%compress
      out%file_open = .true.
      ! the file was cut back: it describes a run going on from here, whatever follows
      call io_write_attribute(out%io, '/run', 'stop_reason', 'running')
      ! a resumed run may be longer or shorter (run.t_end, run.steps): the file says which
      call io_write_attribute(out%io, '/run', 'steps', sim%lp%steps)
      ! (a file of an earlier version has no identity: it gets one now)
      out%run_id = io_run_id(out%io)
      if (out%run_id == 0.0_wp) call new_run_id(out, sim)
      if (sim%dom%rank == 0) call remove_file(dir//'/'//sim%cfg%name//'.finished')
      call log_open(dir//'/'//sim%cfg%name//'.log', err, append=.true.)
      if (len(err) > 0) call fatal_local(err)
      ! the CSV file is written anew from the run file, which holds every value it has
      if (sim%pair_on) call rebuild_csv(out, sim, dir//'/'//sim%cfg%name//'_diagnostics.csv')
      if (allocated(out%restart_changes)) call record_restart_changes(out, sim)
      return
    end if
    ! any file an earlier run of this scene left there (io_open checks the .h5 once more, so
    ! that a file that appears meanwhile is not clobbered)
    call output_check_existing(out, sim)
    call run_lock_take(sim, out%lock_fd)
    call io_open(out%io, dir, sim%cfg%name, sim%dom%comm, sim%lp%nx, sim%dom%ny, sim%dom%y0, &
                 sim%dom%nyl, sim%lp%dx, sim%cfg%output%overwrite, err)
    if (len(err) > 0) call fatal_all(trim(sim%cfg%file)//': output.dir = '''//dir//''': '//err)
    out%io%compress = sim%cfg%output%compress
    out%file_open = .true.
    call log_open(dir//'/'//sim%cfg%name//'.log', err)
    if (len(err) > 0) call fatal_local(err)
    if (sim%dom%rank == 0) then
      call remove_file(dir//'/'//sim%cfg%name//'.finished')
      call remove_file(dir//'/'//sim%cfg%name//'.checkpoint')
    end if

    s = collision_describe(sim%coll)
    ! the lattice parameters in the units of dkt_config; tau, nu_lb and the rates are lattice
    ! numbers, dimensionless
    pnames = [character(len=64) :: 'dx', 'dt', 'tau', 'nu_lb', 's_e', 's_eps', 's_q', 's_nu', &
              'mach']
    pvalues = [sim%lp%dx, sim%lp%dt, sim%lp%tau, sim%lp%nu_lb, s(1), s(2), s(4), s(7), &
               sim%lp%mach]
    ! the input as read (config_load), before &pair and &window expanded
    if (.not. allocated(sim%cfg%given)) call internal_error('output_open: no input text')
    nml = sim%cfg%given
    call io_write_run(out%io, nml, dkt_version_string, dkt_git_revision, sim%dom%nranks, &
                      compiler_version(), dkt_build_flags, pnames, pvalues, &
                      [character(len=2) :: 'cm', 's', '1', '1', '1', '1', '1', '1', '1'])
    call io_write_attribute(out%io, '/run', 'nx', sim%lp%nx)
    call io_write_attribute(out%io, '/run', 'ny', sim%dom%ny)
    ! the rows a growing window may reach (window.max_above), ny when it never grows
    call io_write_attribute(out%io, '/run', 'ny_max', sim%lp%ny_max)
    call io_write_attribute(out%io, '/run', 'steps', sim%lp%steps)
    call write_derived(sim)
    ! replaced when the run ends; a file that still says 'running' is of a run that is going
    ! on or was killed
    call io_write_attribute(out%io, '/run', 'stop_reason', 'running')
    call new_run_id(out, sim)
    if (sim%pair_on .and. sim%dom%rank == 0) then
      ! the pair's series for readers without HDF5; the .h5 beside it was new or overwritable
      open (newunit=out%csv_unit, file=dir//'/'//sim%cfg%name//'_diagnostics.csv', &
            status='replace', action='write', iostat=ios, iomsg=msg)
      if (ios /= 0) call fatal_local(trim(msg))
      out%csv_open = .true.
      write (out%csv_unit, '(a)') CSV_HEADER
    end if
  contains
    !> The scales and thresholds the run uses, as /run attributes, so that readers of the
    !! file need not repeat the program's defaults: t_ref (s), h_ref = g t_ref^2 (cm), gravity
    !! (cm/s^2), width (cm), rho_f (g/cm^3), mu (g/(cm s)); with particles d1 (cm, the larger
    !! diameter of particles 1 and 2); with a pair the diameters of particles 1 and 2 (cm,
    !! diameter_1, diameter_2) and the kissing thresholds in cm (kiss_enter,
    !! kiss_release), in spacings (kiss_enter_cells, kiss_release_cells) and in D_1
    !! (kiss_enter_d1, kiss_release_d1).
    subroutine write_derived(sim)
      type(simulation_t), intent(in) :: sim
      associate (c => sim%cfg)
        call put('t_ref', c%run%t_ref, 's')
        call put('h_ref', c%particles%gravity*c%run%t_ref**2, 'cm')
        call put('gravity', c%particles%gravity, 'cm/s^2')
        call put('width', c%domain%width, 'cm')
        call put('rho_f', c%fluid%density, 'g/cm^3')
        call put('mu', c%fluid%viscosity, 'g/(cm s)')
        if (sim%particles_on) call put('d1', sim%lp%d1, 'cm')
        if (sim%pair_on) then
          call put('diameter_1', c%particles%diameter(1), 'cm')
          call put('diameter_2', c%particles%diameter(2), 'cm')
          call put('kiss_enter', sim%lp%kiss_enter*sim%lp%dx, 'cm')
          call put('kiss_release', sim%lp%kiss_release*sim%lp%dx, 'cm')
          call put('kiss_enter_cells', sim%lp%kiss_enter_cells, '1')
          call put('kiss_release_cells', c%diagnostics%release_cells, '1')
          call put('kiss_enter_d1', c%diagnostics%enter_d1, '1')
          call put('kiss_release_d1', c%diagnostics%release_d1, '1')
        end if
      end associate
    end subroutine write_derived

    subroutine put(name, value, unit)
      character(len=*), intent(in) :: name, unit
      real(wp), intent(in) :: value
      call write_quantity(out%io, '/run', name, value, unit)
    end subroutine put

  end subroutine output_open

  !> The CSV file of the pair (rank 0 writes it) from the run file cut back to the
  !! checkpoint: /diagnostics and particles 1 and 2 of /particles hold every value of its
  !! rows, so the rows are those the run wrote, whatever became of the file (removed,
  !! emptied, cut short, another run's).
  subroutine rebuild_csv(out, sim, path)
    type(output_t), intent(inout) :: out
    type(simulation_t), intent(in) :: sim
    character(len=*), intent(in) :: path
    character(len=7), parameter :: SERIES(6) = &
                                   [character(len=7) :: 't', 'tstar', 'dx', 'dy', 'dr', 'dr_star']
    character(len=7), parameter :: PARTS(5) = &
                                   [character(len=7) :: 'x', 'y', 'u', 'v', 'omega']
    real(wp), allocatable :: d(:, :), re(:, :), cd(:, :), q(:, :), ps(:, :, :)
    character(len=256) :: msg
    integer :: k, n, ios
    n = out%samples
    allocate (d(6, n), ps(2, 5, n))
    do k = 1, 6
      call io_read_series(out%io, 'diagnostics/'//trim(SERIES(k)), q)
      d(k, :) = q(1, 1:n)
    end do
    call io_read_series(out%io, 'diagnostics/re', re)
    call io_read_series(out%io, 'diagnostics/cd', cd)
    do k = 1, 5
      call io_read_series(out%io, 'particles/'//trim(PARTS(k)), q)
      ps(:, k, :) = q(1:2, 1:n)
    end do
    if (sim%dom%rank /= 0) return
    open (newunit=out%csv_unit, file=path, status='replace', action='write', iostat=ios, &
          iomsg=msg)
    if (ios /= 0) call fatal_local('--restart: cannot write '//path//': '//trim(msg))
    out%csv_open = .true.
    write (out%csv_unit, '(a)', iostat=ios, iomsg=msg) CSV_HEADER
    do k = 1, n
      if (ios /= 0) exit
      write (out%csv_unit, '(a)', iostat=ios, iomsg=msg) &
        csv_row(d(:, k), re(:, k), cd(:, k), ps(:, :, k))
    end do
    if (ios == 0) flush (out%csv_unit, iostat=ios, iomsg=msg)
    if (ios /= 0) call fatal_local('--restart: cannot write '//path//': '//trim(msg)// &
                                   '; is the disk full?')
  end subroutine rebuild_csv

  !> The input changes run.restart_changes allowed on resuming: the /run string attribute
  !! restart_changes_step_<step, 9 digits> = 'group.key old -> new; ...' (one per restart that
  !! changed something, so that every change stays recorded), and the stored namelist becomes
  !! the input the run continues with (when it is the attribute /run namelist; the dataset of a
  !! scene of some 500 particles and more keeps the first input).
  subroutine record_restart_changes(out, sim)
    type(output_t), intent(inout) :: out
    type(simulation_t), intent(in) :: sim
    character(len=9) :: digits
    if (len(out%restart_changes) == 0) return
    write (digits, '(i9.9)') sim%step
    call io_write_attribute(out%io, '/run', 'restart_changes_step_'//digits, &
                            out%restart_changes)
    if (len(sim%cfg%given) <= NAMELIST_ATTRIBUTE_MAX) &
      call io_write_attribute(out%io, '/run', 'namelist', sim%cfg%given)
    call log_line('resumed at step '//itoa(sim%step)//' with the changes '// &
                  out%restart_changes//' (run.restart_changes)')
  end subroutine record_restart_changes

  !> Stop every rank, before anything is written, when output.dir cannot take the run's
  !! files: it (or the parent it would be created in) is not a writable directory, or the full
  !! path of a checkpoint file in it is longer than MPI-IO takes (MAX_MPIIO_PATH). The run and
  !! --check both make this check, so that --check refuses what the run would refuse.
  subroutine output_check_dir(sim)
    type(simulation_t), intent(in) :: sim
    character(len=:), allocatable :: dir, err, longest
    integer :: n
    logical :: ok
    dir = sim%cfg%output_dir
    err = ''
    if (sim%dom%rank == 0) then
      err = directory_problem(dir)
      ! the longest path the run opens through MPI-IO (as written: Open MPI does not make it
      ! absolute): a checkpoint while it is written
      longest = dir//'/'//sim%cfg%name//'_chk_000000000.h5.tmp'
      n = len(longest) - len(dir)
      if (len(err) == 0 .and. len(longest) > MAX_MPIIO_PATH) &
        err = 'the path of its checkpoint files, '''//longest//''', is '// &
              itoa(len(longest))//' characters long; allowed: at most '//itoa(MAX_MPIIO_PATH)// &
              ' (longer paths crash the MPI-IO of Open MPI), i.e. an output.dir of at most '// &
              itoa(MAX_MPIIO_PATH - n)//' characters with this scene name'
    end if
    ok = len(err) == 0
    call MPI_Bcast(ok, 1, MPI_LOGICAL, 0, sim%dom%comm)
    ! only rank 0 knows the reason; it is the rank that prints
    if (.not. ok) call fatal_all(trim(sim%cfg%file)//': output.dir = '''//dir//''': '// &
                                 err//'; choose another output.dir')
  end subroutine output_check_dir

  !> Stop every rank when output.dir holds a file of an earlier run of this scene and
  !! output.overwrite is off; the run makes this check before it writes, and --check makes the
  !! same one so that it refuses what the run would refuse. A resumed run continues its files.
  subroutine output_check_existing(out, sim)
    type(output_t), intent(in) :: out
    type(simulation_t), intent(in) :: sim
    !> the files of a run besides <name>.h5, as suffixes of the scene name
    character(len=16), parameter :: RUN_FILES(7) = ['.h5             ', '.log            ', &
                                                    '.xdmf           ', '_particles.xdmf ', &
                                                    '_diagnostics.csv', '.checkpoint     ', &
                                                    '.finished       ']
    character(len=4096) :: found
    character(len=:), allocatable :: dir
    logical :: ok
    integer :: k
    if (sim%cfg%output%overwrite .or. out%resumed) return
    dir = sim%cfg%output_dir
    found = ''
    if (sim%dom%rank == 0) then
      do k = 1, size(RUN_FILES)
        if (path_exists(dir//'/'//sim%cfg%name//trim(RUN_FILES(k)))) &
          found = trim(found)//', '//dir//'/'//sim%cfg%name//trim(RUN_FILES(k))
      end do
    end if
    ok = len_trim(found) == 0
    call MPI_Bcast(ok, 1, MPI_LOGICAL, 0, sim%dom%comm)
    if (.not. ok) call fatal_all(trim(sim%cfg%file)//': output.dir = '''//dir// &
                                 ''' holds files of an earlier run of this scene ('// &
                                 trim(found(3:))//'); set output.overwrite = .true., '// &
                                 'choose another output.dir, or resume with --restart')
  end subroutine output_check_existing

  !> Stop the run on an error all ranks detected together after the output was opened: the
  !! output is completed up to the current step (but for its fields) and closed with
  !! stop_reason 'error: <msg>', then every rank exits with EXIT_RUNTIME and rank 0 prints
  !! `msg`.
  subroutine output_fail(out, sim, msg)
    type(output_t), intent(inout) :: out
    type(simulation_t), intent(in) :: sim
    character(len=*), intent(in) :: msg
    out%stop_reason = 'error: '//msg
    ! the errors here are failed writes, most often a full disk: the fields of this step (the
    ! largest record) are left out so that the series and the stop_reason find the space
    out%fields_step = sim%step
    call output_close(out, sim)
    call fatal_all(msg, EXIT_RUNTIME)
  end subroutine output_fail

  !> The output of the run's last step: the fields and the particle sample unless the
  !! schedule wrote them, and the pair's report.
  subroutine output_final(out, sim)
    type(output_t), intent(inout) :: out
    type(simulation_t), intent(in) :: sim
    if (out%fields_step /= sim%step) call output_fields(out, sim, sim%step)
    if (sim%particles_on .and. out%series_step /= sim%step) &
      call output_particles(out, sim, sim%step)
    if (sim%pair_on .and. .not. out%reported) call output_pair_report(out, sim)
  end subroutine output_final

  !> The fields and the particle sample that fall on step n by output.field_interval and
  !! output.series_interval (the last step's are written by output_final).
  subroutine output_scheduled(out, sim, n)
    type(output_t), intent(inout) :: out
    type(simulation_t), intent(in) :: sim
    integer, intent(in) :: n
    if (sim%lp%field_every > 0) then
      if (mod(n, sim%lp%field_every) == 0) call output_fields(out, sim, n)
    end if
    if (sim%particles_on .and. sim%lp%series_every > 0) then
      if (mod(n, sim%lp%series_every) == 0) call output_particles(out, sim, n)
    end if
  end subroutine output_scheduled

  !> Whether output_scheduled writes the fields of step n, which read the lattice whole.
  pure logical function output_reads_lattice(sim, n) result(reads)
    type(simulation_t), intent(in) :: sim
    integer, intent(in) :: n
    reads = .false.
    if (sim%lp%field_every > 0) reads = mod(n, sim%lp%field_every) == 0
  end function output_reads_lattice

  !> The marker <name>.finished holding the last step, for batch scripts that wait for it.
  !! Written after the output is closed: a run whose marker is there has its output complete.
  subroutine output_mark_finished(sim)
    type(simulation_t), intent(in) :: sim
    character(len=:), allocatable :: path
    logical :: ok
    path = sim%cfg%output_dir//'/'//sim%cfg%name//'.finished'
    ok = .true.
    if (sim%dom%rank == 0) ok = write_marker(path, itoa(sim%step))
    call MPI_Bcast(ok, 1, MPI_LOGICAL, 0, sim%dom%comm)
    if (.not. ok) call fatal_all('cannot write the marker file '''//path//''': the run '// &
                                 'finished and its output is complete, but batch scripts '// &
                                 'that wait for this file will not see it; check that '// &
                                 'output.dir is writable', EXIT_RUNTIME)
  end subroutine output_mark_finished

  !> Complete the output of the current step (the fields and the particle sample unless they
  !! are written, the pair's report), store why the run ended as /run stop_reason and close the
  !! run file and the CSV file. Collective; nothing happens once the output is closed.
  subroutine output_close(out, sim)
    type(output_t), intent(inout) :: out
    type(simulation_t), intent(in) :: sim
    if (.not. out%file_open) return
    call output_final(out, sim)
    call io_write_attribute(out%io, '/run', 'stop_reason', out%stop_reason)
    call io_close(out%io)
    out%file_open = .false.
    if (out%csv_open) close (out%csv_unit)
    out%csv_open = .false.
    call lock_release(out%lock_fd)
  end subroutine output_close

  !> One sample of /particles/{t, x, y, u, v, omega, fx, fy, torque} in physical units (cm, s,
  !! force and torque per unit depth: g/s^2 and g cm/s^2). The force is the hydrodynamic one
  !! of the step that reached time t.
  subroutine output_particles(out, sim, n)
    type(output_t), intent(inout) :: out
    type(simulation_t), intent(in) :: sim
    integer, intent(in) :: n
    real(wp), allocatable :: v(:, :)
    type(particle_t), allocatable :: all(:)
    real(wp) :: dx, dt, fu, y0
    integer :: k
    dx = sim%lp%dx
    dt = sim%lp%dt
    fu = sim%cfg%fluid%density*dx**3/dt**2
    y0 = 0.0_wp
    ! lattice y counts from the window's lower end; the series holds absolute positions
    if (sim%window_on) y0 = window_offset(sim%win, dx)
    ! every particle from its owner
    call particles_gather(sim%parts, sim%dom, all)
    allocate (v(size(all), 8))
    do k = 1, size(all)
      associate (p => all(k))
        v(k, :) = [p%x*dx, p%y*dx + y0, p%u*dx/dt, p%v*dx/dt, p%omega/dt, p%fx*fu, &
                   p%fy*fu, p%torque*fu*dx]
      end associate
    end do
    if (n == 0) call io_write_attribute(out%io, '/particles', 'count', size(all))
    out%samples = out%samples + 1
    out%series_step = n
    call io_write_series(out%io, 'particles', ['t'], [n*dt], ['s'])
    call io_write_table(out%io, 'particles', series_names, v, series_units)
    if (sim%window_on) call io_write_series(out%io, 'particles', ['window_offset'], [y0], ['cm'])
    if (sim%pair_on) call write_pair(out, sim, n, v)
    if (suspension_on(sim)) call write_suspension(out, sim, n, v)
  end subroutine output_particles

  !> A scene of three particles or more is a suspension: /suspension is written with
  !! /particles (docs/suspensions.md).
  pure logical function suspension_on(sim)
    type(simulation_t), intent(in) :: sim
    suspension_on = sim%particles_on .and. sim%cfg%particles%count >= 3
  end function suspension_on

  !> One sample of /suspension (dkt_suspension) from the particle sample `v` (particle,
  !! quantity) in physical units as written to /particles: t, v_mean, v_rms, front,
  !! segregation, and the area-fraction profile phi in bins of the largest diameter.
  subroutine write_suspension(out, sim, n, v)
    type(output_t), intent(inout) :: out
    type(simulation_t), intent(in) :: sim
    integer, intent(in) :: n
    real(wp), intent(in) :: v(:, :)
    real(wp) :: stats(4), bin, height, y0
    real(wp), allocatable :: phi(:)
    associate (c => sim%cfg%particles, lp => sim%lp)
      bin = lp%largest_diameter
      height = sim%dom%ny*lp%dx
      y0 = 0.0_wp
      if (sim%window_on) y0 = window_offset(sim%win, lp%dx)
      allocate (phi(suspension_bins(height, bin)))
      call suspension_stats(v(:, 2) - y0, v(:, 4), lp%particles%r(1:c%count)*lp%dx, &
                            c%motion_kind(1:c%count) == MOTION_FREE, lp%nx*lp%dx, height, &
                            bin, stats, phi)
      if (n == 0) then
        call io_write_attribute(out%io, '/suspension', 'bin', bin)
        call io_write_attribute(out%io, '/suspension', 'front_fraction', FRONT_FRACTION)
      end if
      stats(3) = stats(3) + y0
      call io_write_series(out%io, 'suspension', &
                           [character(len=11) :: 't', 'v_mean', 'v_rms', 'front', 'segregation'], &
                           [n*lp%dt, stats], [character(len=4) :: 's', 'cm/s', 'cm/s', 'cm', '-'])
      call io_write_table(out%io, 'suspension', ['phi'], reshape(phi, [size(phi), 1]), ['-'])
    end associate
  end subroutine write_suspension

  !> A row of the CSV file: the six pair series (t, t*, the gaps), Re and C_d of particles 1 and
  !! 2, then for particles 1 and 2 (p(k, :)) x, y, u, v and omega, in the order of CSV_HEADER.
  pure function csv_row(series, re, cd, p) result(row)
    real(wp), intent(in) :: series(6), re(2), cd(2), p(2, 5)
    character(len=:), allocatable :: row
    character(len=1024) :: buf
    write (buf, '(*(es24.16e3,:,","))') series, re, cd, p(1, 1:2), p(2, 1:2), p(1, 3:4), &
      p(2, 3:4), p(1, 5), p(2, 5)
    row = trim(buf)
  end function csv_row

  !> One sample of /diagnostics (docs/model.md §6) and of the CSV file, from the particle sample `v`
  !! (particle, quantity) in physical units as written to /particles.
  subroutine write_pair(out, sim, n, v)
    type(output_t), intent(inout) :: out
    type(simulation_t), intent(in) :: sim
    integer, intent(in) :: n
    real(wp), intent(in) :: v(:, :)
    real(wp) :: t, gx, gy, gr, d(2), re(2), cd(2), rho_f, mu
    character(len=7) :: names(6)
    character(len=256) :: msg
    integer :: k, ios
    t = n*sim%lp%dt
    rho_f = sim%cfg%fluid%density
    mu = sim%cfg%fluid%viscosity
    d = 2.0_wp*sim%lp%particles%r(1:2)*sim%lp%dx
    call pair_gaps(v(1, 1), v(1, 2), 0.5_wp*d(1), v(2, 1), v(2, 2), 0.5_wp*d(2), gx, gy, gr)
    do k = 1, 2
      re(k) = rho_f*hypot(v(k, 3), v(k, 4))*d(k)/mu
      cd(k) = drag_coefficient(v(k, 7), v(k, 3), v(k, 4), rho_f, d(k))
    end do
    names = [character(len=7) :: 't', 'tstar', 'dx', 'dy', 'dr', 'dr_star']
    call io_write_series(out%io, 'diagnostics', names, &
                         [t, t/sim%cfg%run%t_ref, gx, gy, gr, gr/maxval(d)], &
                         [character(len=2) :: 's', '1', 'cm', 'cm', 'cm', '1'])
    call io_write_table(out%io, 'diagnostics', ['re', 'cd'], reshape([re, cd], [2, 2]), &
                        ['1', '1'])
    if (out%csv_open) then
      write (out%csv_unit, '(a)', iostat=ios, iomsg=msg) &
        csv_row([t, t/sim%cfg%run%t_ref, gx, gy, gr, gr/maxval(d)], re, cd, &
                v(1:2, 1:5))
      ! kept on disk row by row: a rank that aborts the job must not take the series with it
      if (ios == 0) flush (out%csv_unit, iostat=ios, iomsg=msg)
      ! rank 0 alone writes it: it ends the job (a full disk)
      if (ios /= 0) call fatal_local('cannot write the CSV file '''// &
                                     sim%cfg%output_dir//'/'//sim%cfg%name// &
                                     '_diagnostics.csv'': '//trim(msg)//'; is the disk full?')
    end if
  end subroutine write_pair

  !> At the end of a run with a pair: the pattern and its episodes into /diagnostics and the
  !! log, with the thresholds they were found with.
  subroutine output_pair_report(out, sim)
    type(output_t), intent(inout) :: out
    type(simulation_t), intent(in) :: sim
    real(wp) :: dx, d(2), gamma, dh
    character(len=7), parameter :: episode_names(3) = ['start  ', 'end    ', 'gap_min']
    character(len=256) :: line
    character(len=:), allocatable :: pattern
    integer :: k
    dx = sim%lp%dx
    pattern = pair_pattern(sim%pair)
    out%reported = .true.
    associate (cp => sim%cfg%particles, e => sim%pair)
      d = cp%diameter(1:2)
      gamma = maxval(d)/minval(d)
      dh = abs(cp%y(1) - cp%y(2))/maxval(d)
      call io_write_attribute(out%io, '/diagnostics', 'pattern', pattern)
      call io_write_attribute(out%io, '/diagnostics', 'episodes', e%n)
      call io_write_attribute(out%io, '/diagnostics', 'open_episode', merge(1, 0, e%in_episode))
      call put('kiss_enter', e%enter*dx, 'cm')
      call put('kiss_release', e%release*dx, 'cm')
      call put('kiss_enter_cells', sim%lp%kiss_enter_cells, '1')
      call put('kiss_release_cells', sim%cfg%diagnostics%release_cells, '1')
      call put('d1', sim%lp%d1, 'cm')
      call put('gamma', gamma, '1')
      call put('dh', dh, '1')
      call put('t_ref', sim%cfg%run%t_ref, 's')
      call put('h_ref', cp%gravity*sim%cfg%run%t_ref**2, 'cm')
      call put('gravity', cp%gravity, 'cm/s^2')
      call put('width', sim%cfg%domain%width, 'cm')
      call io_write_attribute(out%io, '/diagnostics', 'ended_early', &
                              merge(0, 1, out%stop_reason == 'finished'))
      do k = 1, e%n
        call io_write_series(out%io, 'diagnostics/episodes', episode_names, &
                             [e%t_start(k), e%t_end(k), e%gap_min(k)*dx], ['s ', 's ', 'cm'])
      end do
      write (line, '(a,f5.2,a,f6.2,a)') 'DKT pattern: '//pattern//' (gamma = ', gamma, &
        ', D_h/D_1 = ', dh, '; '
      call log_line(trim(line)//' '//counted(e%n, 'kissing episode')//')')
      do k = 1, e%n
        write (line, '(a,i0,a,f8.4,a,f8.4,a,f7.3,a,f7.3,a,f7.4,a)') '  episode ', k, ': t = ', &
          e%t_start(k), ' .. ', e%t_end(k), ' s (t* = ', e%t_start(k)/sim%cfg%run%t_ref, &
          ' .. ', e%t_end(k)/sim%cfg%run%t_ref, '), smallest D_r = ', e%gap_min(k)*dx, ' cm'
        if (k == e%n .and. e%in_episode) line = trim(line)//', still open at the end'
        call log_line(trim(line))
      end do
      write (line, '(a,f7.4,a,f5.2,a,f7.4,a,f5.2,a)') '  thresholds: enter D_r <= ', &
        e%enter*dx, ' cm (', e%enter, ' spacings), release D_r > ', e%release*dx, ' cm (', &
        e%release, ' spacings)'
      call log_line(trim(line))
    end associate
  contains
    subroutine put(name, value, unit)
      character(len=*), intent(in) :: name, unit
      real(wp), intent(in) :: value
      call write_quantity(out%io, '/diagnostics', name, value, unit)
    end subroutine put
  end subroutine output_pair_report

  !> Attribute `name` of the object at `path` and its unit as the string attribute
  !! `name`_units (HDF5 has no attributes of attributes).
  subroutine write_quantity(io, path, name, value, unit)
    type(io_t), intent(inout) :: io
    character(len=*), intent(in) :: path, name, unit
    real(wp), intent(in) :: value
    call io_write_attribute(io, path, name, value)
    call io_write_attribute(io, path, name//'_units', unit)
  end subroutine write_quantity

  !> Fields in physical units: rho (g/cm^3), ux, uy (cm/s), vorticity (1/s), pressure
  !! deviation c_s^2 (rho - rho_f) (g/(cm s^2)); with particles the particle number of each node
  !! and the disks (centre, velocity, angular velocity, radius) at this step.
  subroutine output_fields(out, sim, n)
    type(output_t), intent(inout) :: out
    type(simulation_t), intent(in) :: sim
    integer, intent(in) :: n
    real(wp), allocatable :: fld(:, :, :), id(:, :), disks(:, :)
    type(particle_t), allocatable :: all(:)
    real(wp) :: uc, y0
    integer :: k
    associate (lp => sim%lp, nx => sim%dom%nx, nyl => sim%dom%nyl)
      allocate (fld(nx, nyl, 5))
      call macroscopic(sim%dom, sim%f, lp%force_lb, fld(:, :, 1), fld(:, :, 2), fld(:, :, 3))
      call vorticity(sim%dom, fld(:, :, 2), fld(:, :, 3), sim%bc%periodic_x, fld(:, :, 4))
      uc = lp%dx/lp%dt
      fld(:, :, 5) = cs2*(fld(:, :, 1) - 1.0_wp)*sim%cfg%fluid%density*uc*uc
      fld(:, :, 1) = fld(:, :, 1)*sim%cfg%fluid%density
      fld(:, :, 2:3) = fld(:, :, 2:3)*uc
      fld(:, :, 4) = fld(:, :, 4)/lp%dt
      y0 = 0.0_wp
      if (sim%window_on) y0 = window_offset(sim%win, lp%dx)
      call check_field_space(out, sim, n)
      out%fields_step = n
      ! the rows of this step: a window that grows has more than at the open
      call io_set_rows(out%io, sim%dom%ny, sim%dom%y0, sim%dom%nyl)
      if (sim%particles_on) then
        call particles_gather(sim%parts, sim%dom, all)
        allocate (id(nx, nyl), disks(size(all), 6))
        call particles_solid_field(sim%parts, sim%dom, id)
        do k = 1, size(all)
          associate (p => all(k))
            ! as the /particles series computes them, so both hold the same bits
            disks(k, :) = [p%x*lp%dx, p%y*lp%dx + y0, p%u*lp%dx/lp%dt, p%v*lp%dx/lp%dt, &
                           p%omega/lp%dt, p%r*lp%dx]
          end associate
        end do
        call io_write_fields(out%io, n, n*lp%dt, y0, field_names, fld, field_units, &
                             solid=nint(id), disks=disks)
      else
        call io_write_fields(out%io, n, n*lp%dt, y0, field_names, fld, field_units)
      end if
    end associate
  end subroutine output_fields

  !> The space of the field snapshot of step n first (its values, uncompressed, and 256 KiB for
  !! the series held in memory): a parallel HDF5 write that fails for want of space cannot be
  !! recovered (dkt_checkpoint). Without it the run stops as output_fail stops it: the series
  !! written, stop_reason naming the full disk, one line, exit status 3.
  subroutine check_field_space(out, sim, n)
    type(output_t), intent(inout) :: out
    type(simulation_t), intent(in) :: sim
    integer, intent(in) :: n
    character(len=:), allocatable :: err
    integer(c_long) :: bytes
    logical :: ok
    bytes = int(sim%lp%nx, c_long)*int(sim%dom%ny, c_long)*48_c_long + 262144_c_long
    err = ''
    if (sim%dom%rank == 0) err = space_problem(sim%cfg%output_dir, sim%cfg%name//'.space', bytes)
    ok = len(err) == 0
    call MPI_Bcast(ok, 1, MPI_LOGICAL, 0, sim%dom%comm)
    ! (rank 0's reason: the rank that prints and stores it)
    if (.not. ok) &
      call output_fail(out, sim, 'cannot write the field snapshot of step '//itoa(n)//' into '''// &
                       sim%cfg%output_dir//'/'//sim%cfg%name//'.h5'': '//err//' (it needs '// &
                       itoa(int(bytes/1024_c_long))//' KiB in output.dir); is the disk full?')
  end subroutine check_field_space

end module dkt_output

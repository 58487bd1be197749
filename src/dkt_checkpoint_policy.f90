!> When the run writes checkpoints and what it does around them: every run.checkpoint_every
!> steps, every run.checkpoint_wall seconds, before stopping on a signal or at run.wall_limit,
!> and at the last step; the marker <name>.checkpoint naming the newest, the older ones removed
!> beyond run.checkpoint_keep; the command that resumes; and the resumption itself.
module dkt_checkpoint_policy
  use mpi_f08, only: MPI_Wtime, MPI_Bcast, MPI_LOGICAL, MPI_Iallreduce, MPI_Wait, MPI_Request, &
                     MPI_STATUS_IGNORE, MPI_INTEGER, MPI_BOR, MPI_Comm
  use dkt_kinds, only: wp
  use dkt_errors, only: fatal_all, warn
  use dkt_config, only: config_t, lattice_params_t
  use dkt_particles, only: particle_t, particles_gather, particles_distribute
  use dkt_links, only: links_find
  use dkt_checkpoint, only: checkpoint_t, checkpoint_write, checkpoint_read, checkpoint_name, &
                            checkpoint_rows, &
                            NSTATE, STORAGE_NAMES
  use dkt_signals, only: signals_install, signal_mask, signal_name
  use dkt_log, only: log_line
  use dkt_filesystem, only: remove_file, write_marker
  use dkt_text, only: itoa
  use dkt_run_state, only: simulation_t
  use dkt_simulation, only: simulation_grow
  use dkt_restart_check, only: restart_problem, run_file_problem
  use dkt_store, only: lattice_precision_name
  use dkt_output, only: output_t, output_fail, output_resume, output_set_stop_reason, &
                        output_flush, output_samples, output_run_id
  implicit none
  private
  public :: checkpoint_state_t, checkpoint_start, checkpoint_due, checkpoint_finish, &
            checkpoint_final, checkpoint_stop_message, checkpoint_resume, &
            checkpoint_interrupted, input_check_i, resume_rows, checkpoint_poll

  integer, parameter :: SIGNAL_SHIFT = 3 !! the flag bits of the signals start after bit 2

  abstract interface
    !> The comparison of the input with the one `stored` in the checkpoint at `path`, which
    !! stops the run on a change of the physics beyond run.restart_changes and returns the
    !! changes it allows in `record` (the input layer's restart_input_check).
    subroutine input_check_i(cfg, stored, path, record)
      import :: config_t
      type(config_t), intent(in) :: cfg
      character(len=*), intent(in) :: stored, path
      character(len=:), allocatable, intent(out) :: record
    end subroutine input_check_i
  end interface

  !> a file name, as an element of a list of names of different lengths
  type :: path_t
    character(len=:), allocatable :: s
  end type path_t

  !> The checkpoints' state, owned by this module: the clocks, the flags and the checkpoints
  !! written. The ranks agree on the signal and clock flags with a reduction started one step
  !! earlier, so that no step waits for it; every rank acts on the same flags at the same step.
  !! Bit 0: a signal arrived; bit 1: run.checkpoint_wall passed; bit 2: run.wall_limit passed;
  !! bits SIGNAL_SHIFT + s: signal s arrived (dkt_signals signal_mask).
  type :: checkpoint_state_t
    private
    integer :: flags_out = 0, flags_in = 0 !! buffers of the flag reduction in flight
    integer :: flags = 0 !! the flags of the reduction completed for this step (checkpoint_poll)
    type(MPI_Request) :: request
    logical :: pending = .false.
    real(wp) :: t_start = 0.0_wp       !! wall time at the first step (run.wall_limit)
    real(wp) :: t_checkpoint = 0.0_wp  !! wall time of the last checkpoint (checkpoint_wall)
    character(len=:), allocatable :: reason !! why the run stopped to be resumed, for the log
    logical :: interrupted = .false. !! stopped on a signal or the wall limit, to be resumed
    type(path_t), allocatable :: checkpoints(:)  !! written by this run (and the one resumed)
  end type checkpoint_state_t

contains

  !> Install the signal handlers and start the clocks, before the first step.
  subroutine checkpoint_start(state)
    type(checkpoint_state_t), intent(inout), asynchronous :: state
    call signals_install()
    state%t_start = MPI_Wtime()
    state%t_checkpoint = state%t_start
    state%pending = .false.
    state%reason = ''
  end subroutine checkpoint_start

  !> After each step: write the checkpoints that are due. `stop` = .true. when the run wrote
  !! a checkpoint on a signal or at the wall limit and ends here to be resumed. At the `last`
  !! step nothing is written (a checkpoint at the last step follows the final output).
  subroutine checkpoint_due(state, out, sim, last, stop)
    type(checkpoint_state_t), intent(inout), asynchronous :: state
    type(output_t), intent(inout) :: out
    type(simulation_t), intent(in) :: sim
    logical, intent(in) :: last
    logical, intent(out) :: stop
    integer :: flags
    stop = .false.
    call complete_flags(state)
    flags = state%flags
    state%flags = 0
    if (.not. last .and. (btest(flags, 0) .or. btest(flags, 2))) then
      call checkpoint_save(state, out, sim)
      state%interrupted = .true.
      if (btest(flags, 0)) then
        ! the signals any rank caught, so that rank 0's log names one even when only
        ! another rank was signalled
        state%reason = 'on signal '//signal_name(ishft(flags, -SIGNAL_SHIFT))
        call output_set_stop_reason(out, 'signal')
      else
        state%reason = 'at run.wall_limit'
        call output_set_stop_reason(out, 'wall_limit')
      end if
      stop = .true.
      return
    end if
    if (last) return
    if (btest(flags, 1) .or. sim%cfg%run%checkpoint_every > 0) then
      if (btest(flags, 1) .or. mod(sim%step, max(1, sim%cfg%run%checkpoint_every)) == 0) then
        call checkpoint_save(state, out, sim)
        state%t_checkpoint = MPI_Wtime()
      end if
    end if
    state%flags_out = 0
    if (signal_mask() /= 0) state%flags_out = ior(ibset(state%flags_out, 0), &
                                                  ishft(signal_mask(), SIGNAL_SHIFT))
    if (sim%dom%rank == 0) then
      if (sim%cfg%run%checkpoint_wall > 0.0_wp .and. &
          MPI_Wtime() - state%t_checkpoint >= sim%cfg%run%checkpoint_wall) &
        state%flags_out = ibset(state%flags_out, 1)
      if (sim%cfg%run%wall_limit > 0.0_wp .and. &
          MPI_Wtime() - state%t_start >= sim%cfg%run%wall_limit) &
        state%flags_out = ibset(state%flags_out, 2)
    end if
    call MPI_Iallreduce(state%flags_out, state%flags_in, 1, MPI_INTEGER, MPI_BOR, &
                        sim%dom%comm, state%request)
    state%pending = .true.
  end subroutine checkpoint_due

  !> Before checkpoint_due: whether it writes a checkpoint at this step (a signal, the wall
  !! limit or run.checkpoint_wall that a rank saw by the step before, or run.checkpoint_every),
  !! so that the caller completes the lattice first. Completes the flag reduction in flight.
  subroutine checkpoint_poll(state, sim, last, writes)
    type(checkpoint_state_t), intent(inout), asynchronous :: state
    type(simulation_t), intent(in) :: sim
    logical, intent(in) :: last
    logical, intent(out) :: writes
    call complete_flags(state)
    writes = .false.
    if (last) return
    writes = btest(state%flags, 0) .or. btest(state%flags, 1) .or. btest(state%flags, 2)
    if (sim%cfg%run%checkpoint_every > 0) &
      writes = writes .or. mod(sim%step, sim%cfg%run%checkpoint_every) == 0
  end subroutine checkpoint_poll

  !> The flags every rank raised by the step before (state%flags), once their reduction is
  !! complete; nothing when none is in flight.
  subroutine complete_flags(state)
    type(checkpoint_state_t), intent(inout), asynchronous :: state
    if (.not. state%pending) return
    call MPI_Wait(state%request, MPI_STATUS_IGNORE)
    state%flags = state%flags_in
    state%pending = .false.
  end subroutine complete_flags

  !> After the loop: complete the flag reduction still in flight (a guard stop leaves the one
  !! of the step before).
  subroutine checkpoint_finish(state)
    type(checkpoint_state_t), intent(inout), asynchronous :: state
    if (state%pending) call MPI_Wait(state%request, MPI_STATUS_IGNORE)
    state%pending = .false.
  end subroutine checkpoint_finish

  !> At the end of a finished run: a checkpoint at the last step lets the run be extended (a
  !! larger run.t_end); the final sample counts only when it is on the series schedule, as in a
  !! longer run.
  subroutine checkpoint_final(state, out, sim)
    type(checkpoint_state_t), intent(inout) :: state
    type(output_t), intent(inout) :: out
    type(simulation_t), intent(in) :: sim
    if (sim%cfg%run%checkpoint_every > 0) then
      if (mod(sim%step, sim%cfg%run%checkpoint_every) == 0) &
        call checkpoint_save(state, out, sim, merge(1, 0, sim%particles_on .and. &
                                                    mod(sim%step, sim%lp%series_every) /= 0))
    end if
  end subroutine checkpoint_final

  !> Whether the run stopped on a signal or at run.wall_limit, to be resumed.
  pure logical function checkpoint_interrupted(state)
    type(checkpoint_state_t), intent(in) :: state
    checkpoint_interrupted = state%interrupted
  end function checkpoint_interrupted

  !> The log lines of a run stopped to be resumed: why, where, and the command that resumes.
  subroutine checkpoint_stop_message(state, sim)
    type(checkpoint_state_t), intent(in) :: state
    type(simulation_t), intent(in) :: sim
    call log_line('stopped '//state%reason//' after step '//itoa(sim%step)//' of '// &
                  itoa(sim%lp%steps)//'; checkpoint '// &
                  state%checkpoints(size(state%checkpoints))%s//' written. Resume with:')
    call log_line('  '//resume_command(state%checkpoints(size(state%checkpoints))%s, &
                                       sim%dom%nranks))
  end subroutine checkpoint_stop_message

  !> Continue from the checkpoint at `path` (written by this scene on any number of ranks): the
  !! populations, the particles, the window, the kissing episodes and the step. A checkpoint of
  !! another lattice or time step, or with another number of particles, stops every rank, as
  !! does an input that changes the checkpoint's physics beyond run.restart_changes
  !! (`input_check`, after the checks of the lattice, the precision and the step).
  subroutine checkpoint_resume(state, out, sim, path, input_check)
    type(checkpoint_state_t), intent(inout) :: state
    type(output_t), intent(inout) :: out
    type(simulation_t), intent(inout) :: sim
    character(len=*), intent(in) :: path
    procedure(input_check_i) :: input_check
    type(checkpoint_t) :: chk
    character(len=:), allocatable :: err, changes
    character(len=512) :: msg
    type(particle_t), allocatable :: all(:)
    integer :: k
    call checkpoint_read(path, sim%dom%comm, sim%f, sim%lp%nx, sim%dom%ny, sim%dom%nyl, &
                         sim%dom%y0, chk, err)
    if (len(err) > 0) call fatal_all('--restart '//path//': '//err)
    if (grown_to(sim, chk%ny)) then
      ! written after the window grew (docs/model.md §5): the lattice of that size, then its
      ! populations, which the read puts in place of those the growth moved
      call simulation_grow(sim, chk%ny)
      call checkpoint_read(path, sim%dom%comm, sim%f, sim%lp%nx, sim%dom%ny, sim%dom%nyl, &
                           sim%dom%y0, chk, err)
      if (len(err) > 0) call fatal_all('--restart '//path//': '//err)
    end if
    if (chk%nx /= sim%lp%nx .or. chk%ny /= sim%dom%ny .or. &
        abs(chk%dx - sim%lp%dx) > 1.0e-12_wp*sim%lp%dx .or. &
        abs(chk%dt - sim%lp%dt) > 1.0e-12_wp*sim%lp%dt .or. &
        chk%np /= merge(sim%parts%ntotal, 0, sim%particles_on)) then
      write (msg, '(a,i0,a,i0,a,es12.5,a,es12.5,a,i0,a,i0,a,i0,a,es12.5,a,es12.5,a,i0,a)') &
        ': the checkpoint holds a lattice of ', chk%nx, ' x ', chk%ny, ' cells, dx = ', chk%dx, &
        ' cm, dt = ', chk%dt, ' s with ', chk%np, ' particles; the scene '// &
        'gives ', sim%lp%nx, ' x ', sim%dom%ny, ', dx = ', sim%lp%dx, ', dt = ', sim%lp%dt, &
        ' with ', merge(sim%parts%ntotal, 0, sim%particles_on), '. Resume with the scene '// &
        'file and --set options of the run that wrote it'
      call fatal_all(trim(sim%cfg%file)//': --restart '//path//trim(msg))
    end if
    if (STORAGE_NAMES(chk%precision) /= lattice_precision_name(sim%f)) then
      ! a 4-byte lattice cannot take 8-byte values exactly, nor a shifted one unshifted ones
      call fatal_all(trim(sim%cfg%file)//': --restart '//path//': the checkpoint stores its '// &
                     'populations with lbm.precision = '''//trim(STORAGE_NAMES(chk%precision))// &
                     '''; the scene gives '''//lattice_precision_name(sim%f)//'''. Resume '// &
                     'with the precision of the run that wrote it: --set lbm.precision='// &
                     trim(STORAGE_NAMES(chk%precision)))
    end if
    if (chk%step > sim%lp%steps) then
      write (msg, '(a,i0,a,i0,a)') ': the checkpoint is at step ', chk%step, &
        ', beyond the last step ', sim%lp%steps, ' of the scene; raise run.t_end to continue'
      call fatal_all(trim(sim%cfg%file)//': --restart '//path//trim(msg))
    end if
    ! the physics of its input (a lattice of other sizes was refused above with its sizes)
    call input_check(sim%cfg, chk%given, path, changes)
    ! the run file it continues is the one its run wrote, not another run's file
    err = run_file_problem(sim, chk)
    if (len(err) > 0) call fatal_all(trim(sim%cfg%file)//': --restart '//path//': '//err)
    ! its values against the scene and the run file, before anything is cut or overwritten
    err = restart_problem(sim, chk, path)
    if (len(err) > 0) call fatal_all(trim(sim%cfg%file)//': --restart '//path//': restart '// &
                                     'file '''//path//''' is damaged or not of this run: '// &
                                     err//'; use an earlier checkpoint')
    if (.not. chk%checksums) &
      call warn('--restart '//path//': the checkpoint has no checksums (written by an earlier '// &
                'version): its values were checked against their bounds, but a damaged '// &
                'byte within them would go unnoticed')
    sim%step = chk%step
    sim%win%shift = chk%shift
    if (sim%particles_on) then
      ! every particle as the checkpoint holds it, each slab then keeping its own and its ghosts
      call particles_gather(sim%parts, sim%dom, all)
      do k = 1, size(chk%particles, 2)
        associate (p => all(k), v => chk%particles(:, k))
          p%x = v(1); p%y = v(2); p%u = v(3); p%v = v(4); p%omega = v(5)
          p%fx = v(6); p%fy = v(7); p%torque = v(8); p%cx = v(9); p%cy = v(10)
        end associate
      end do
      call particles_distribute(sim%parts, sim%dom, all)
      call links_find(sim%links, sim%parts, sim%dom)
    end if
    if (sim%pair_on) then
      sim%pair%n = size(chk%t_start)
      sim%pair%in_episode = chk%in_episode
      sim%pair%t_start = chk%t_start
      sim%pair%t_end = chk%t_end
      sim%pair%gap_min = chk%gap_min
    end if
    call output_resume(out, path, chk%samples, changes)
    state%checkpoints = [path_t(path)]
  end subroutine checkpoint_resume

  !> Whether a window that grows (window.max_above) reaches ny rows from the scene's: by
  !! lattice_params_t grow_rows at a time, up to ny_max. Any other row count is another lattice.
  pure logical function grown_to(sim, ny)
    type(simulation_t), intent(in) :: sim
    integer, intent(in) :: ny
    grown_to = sim%window_on .and. window_grows_to(sim%lp, ny)
  end function grown_to

  !> Whether a window of the lattice `lp` that grows (window.max_above) can reach ny rows.
  pure logical function window_grows_to(lp, ny)
    type(lattice_params_t), intent(in) :: lp
    integer, intent(in) :: ny
    window_grows_to = .false.
    if (lp%grow_rows < 1) return
    if (ny <= lp%ny .or. ny > lp%ny_max) return
    window_grows_to = ny == lp%ny_max .or. mod(ny - lp%ny, lp%grow_rows) == 0
  end function window_grows_to

  !> The rows a run resumed from the checkpoint at `path` starts with: those of its lattice when
  !! the window had grown to them, so that the slabs are judged and split on the lattice the
  !! run continues on (a grown window may allow more ranks than the first one), else lp%ny.
  integer function resume_rows(lp, window_on, path, comm) result(ny)
    type(lattice_params_t), intent(in) :: lp
    logical, intent(in) :: window_on
    character(len=*), intent(in) :: path
    type(MPI_Comm), intent(in) :: comm
    ny = lp%ny
    if (.not. window_on .or. lp%grow_rows < 1) return
    ny = checkpoint_rows(path, comm)
    if (.not. window_grows_to(lp, ny)) ny = lp%ny
  end function resume_rows

  !> Write the checkpoint of the current step, name it in <dir>/<name>.checkpoint and delete
  !! the checkpoints beyond run.checkpoint_keep. A failed write stops the run; the checkpoint
  !! written before stays as it was.
  subroutine checkpoint_save(state, out, sim, unscheduled)
    type(checkpoint_state_t), intent(inout) :: state
    type(output_t), intent(inout) :: out
    type(simulation_t), intent(in) :: sim
    integer, intent(in), optional :: unscheduled !! samples written off the series schedule
    type(checkpoint_t) :: chk
    character(len=:), allocatable :: dir, path, err, before
    type(particle_t), allocatable :: all(:)
    integer :: k
    logical :: ok
    dir = sim%cfg%output_dir
    path = checkpoint_name(dir, sim%cfg%name, sim%step)
    chk%step = sim%step
    chk%shift = sim%win%shift
    chk%samples = output_samples(out)
    if (present(unscheduled)) chk%samples = output_samples(out) - unscheduled
    chk%nx = sim%lp%nx
    chk%ny = sim%dom%ny
    chk%dx = sim%lp%dx
    chk%dt = sim%lp%dt
    chk%run_id = output_run_id(out)
    allocate (chk%particles(NSTATE, merge(sim%parts%ntotal, 0, sim%particles_on)))
    if (sim%particles_on) call particles_gather(sim%parts, sim%dom, all)
    do k = 1, size(chk%particles, 2)
      associate (p => all(k))
        chk%particles(:, k) = [p%x, p%y, p%u, p%v, p%omega, p%fx, p%fy, p%torque, p%cx, p%cy]
      end associate
    end do
    chk%in_episode = sim%pair_on .and. sim%pair%in_episode
    if (sim%pair_on) then
      chk%t_start = sim%pair%t_start(1:sim%pair%n)
      chk%t_end = sim%pair%t_end(1:sim%pair%n)
      chk%gap_min = sim%pair%gap_min(1:sim%pair%n)
    else
      allocate (chk%t_start(0), chk%t_end(0), chk%gap_min(0))
    end if
    ! the run file first holds every sample the checkpoint counts, so that a run killed later
    ! resumes onto complete series (samples are held in memory between flushes, dkt_io)
    call output_flush(out)
    call checkpoint_write(path, sim%dom%comm, sim%f, sim%lp%nx, sim%dom%nyl, sim%dom%y0, chk, &
                          sim%cfg%given, err)
    if (len(err) > 0) then
      before = 'none'
      if (allocated(state%checkpoints)) then
        if (size(state%checkpoints) > 0) before = state%checkpoints(size(state%checkpoints))%s
      end if
      call output_fail(out, sim, err//'. The last checkpoint written is '//before)
    end if
    if (.not. allocated(state%checkpoints)) allocate (state%checkpoints(0))
    state%checkpoints = [state%checkpoints, path_t(path)]
    ok = .true.
    if (sim%dom%rank == 0) ok = write_marker(dir//'/'//sim%cfg%name//'.checkpoint', path)
    call MPI_Bcast(ok, 1, MPI_LOGICAL, 0, sim%dom%comm)
    ! batch scripts resume from the checkpoint the marker names: a stale one would lose steps
    if (.not. ok) call output_fail(out, sim, 'cannot write the marker file '''//dir//'/'// &
                                   sim%cfg%name//'.checkpoint'' naming the checkpoint '// &
                                   path//'; check that output.dir is writable')
    do while (size(state%checkpoints) > sim%cfg%run%checkpoint_keep)
      if (sim%dom%rank == 0) call remove_file(state%checkpoints(1)%s)
      state%checkpoints = state%checkpoints(2:)
    end do
    call log_line('checkpoint '//path)
  end subroutine checkpoint_save

  !> The command that resumes this run from `checkpoint`: this process's arguments with
  !! --restart replaced, under mpirun with the same rank count.
  function resume_command(checkpoint, nranks) result(cmd)
    character(len=*), intent(in) :: checkpoint
    integer, intent(in) :: nranks
    character(len=:), allocatable :: cmd, arg
    integer :: j, length
    logical :: skip
    cmd = 'mpirun -n '//itoa(nranks)
    skip = .false.
    do j = 0, command_argument_count()
      call get_command_argument(j, length=length)
      allocate (character(len=length) :: arg)
      call get_command_argument(j, arg)
      if (skip) then
        skip = .false.
      else if (arg == '--restart') then
        skip = .true.
      else if (index(arg, '--restart=') /= 1) then
        if (index(arg, ' ') > 0 .or. len(arg) == 0) then
          cmd = cmd//' '''//arg//''''
        else
          cmd = cmd//' '//arg
        end if
      end if
      deallocate (arg)
    end do
    cmd = cmd//' --restart '//checkpoint
  end function resume_command

end module dkt_checkpoint_policy

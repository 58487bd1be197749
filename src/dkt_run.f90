!> One run: the solver's state (simulation_t) and the services' own (output_t,
!> checkpoint_state_t), set up from the checked input, stepped through the time loop and
!> finished. The driver calls run_setup, run_execute and run_finish.
module dkt_run
  use ieee_arithmetic, only: ieee_support_underflow_control, ieee_set_underflow_mode
  use mpi_f08, only: MPI_Comm
  use dkt_kinds, only: wp, sp
  use dkt_errors, only: fatal_all, warn, EXIT_RUNTIME
  use dkt_config, only: config_t, lattice_params_t
  use dkt_diagnostics, only: guard_check
  use dkt_window, only: window_offset
  use dkt_log, only: log_line
  use dkt_text, only: itoa
  use dkt_timers, only: timer_reset, timer_start, timer_stop, PART_GUARDS, PART_OUTPUT, &
                        PART_CHECKPOINTS
  use dkt_simulation, only: simulation_t, simulation_setup, simulation_step, simulation_finish, &
                            simulation_settle
  use dkt_output, only: output_t, output_open, output_check_dir, output_check_existing, &
                        output_initial, output_scheduled, output_final, output_close, &
                        output_mark_finished, output_free, output_set_stop_reason, &
                        output_reads_lattice
  use dkt_report, only: progress_t, report_summary, report_start, report_progress, &
                        report_performance
  use dkt_checkpoint_policy, only: checkpoint_state_t, checkpoint_resume, checkpoint_start, &
                                   checkpoint_poll, checkpoint_due, checkpoint_finish, &
                                   checkpoint_final, checkpoint_stop_message, input_check_i, &
                                   resume_rows
  use dkt_stop, only: stop_t, stop_after_step, stop_set, stop_failed, stop_last, STOP_FINISHED, &
                      STOP_WINDOW, STOP_PARTICLE, STOP_GUARD, STOP_INTERRUPTED, STOP_NONE
  implicit none
  private
  public :: run_t, run_setup, run_execute, run_finish

  !> the state of one run: the solver's and each service's
  type :: run_t
    type(simulation_t) :: sim
    type(output_t) :: out          !! the run file, the CSV file and their counters
    type(checkpoint_state_t) :: chk !! the checkpoints written, the clocks and the flags
  end type run_t

contains

  !> Set the run up: decompose, allocate and initialise (simulation_setup), check output.dir,
  !! resume from the checkpoint `restart` (when not ''), print the start-up summary and open
  !! the output. `check` (--check) sets up all but the lattices, reports, and refuses what the
  !! run would refuse, writing nothing.
  subroutine run_setup(run, cfg, lp, comm, restart, check, input_check)
    type(run_t), intent(inout) :: run
    type(config_t), intent(in) :: cfg
    type(lattice_params_t), intent(in) :: lp
    type(MPI_Comm), intent(in) :: comm
    character(len=*), intent(in) :: restart
    logical, intent(in) :: check
    !> the input layer's comparison of the input with the one stored in the checkpoint
    procedure(input_check_i) :: input_check
    integer :: ny
    ! a resumed run starts on its checkpoint's lattice, which a window may have grown
    ny = lp%ny
    if (len(restart) > 0) ny = resume_rows(lp, cfg%window%enabled, restart, comm)
    call simulation_setup(run%sim, cfg, lp, comm, ny, lattices=.not. check)
    call output_check_dir(run%sim)
    if (len(restart) > 0 .and. .not. check) &
      call checkpoint_resume(run%chk, run%out, run%sim, restart, input_check)
    call report_summary(run%sim)
    if (check) then
      if (len(restart) == 0) call output_check_existing(run%out, run%sim)
    else
      call output_open(run%out, run%sim)
    end if
  end subroutine run_setup

  !> The time loop (docs/model.md §1–2): a step of the solver, the lattice completed when it is
  !! read, the guards, the output with the progress line, the checkpoints, each one call into
  !! its own module, and one decision whether the loop ends (stop_t, which the step, the guards
  !! and the checkpoints fill); then the run ends as that decision's kind says.
  subroutine run_execute(run)
    type(run_t), intent(inout), asynchronous :: run
    type(progress_t) :: prog
    type(stop_t) :: stop
    integer :: n
    real(wp) :: t, mach, y0
    character(len=:), allocatable :: placed

    associate (sim => run%sim, out => run%out, chk => run%chk, lp => run%sim%lp)
      ! 4-byte arithmetic on deviations (lbm.precision = 'single_arith' and 'half'): the
      ! quiescent fluid ahead of a disturbance holds deviations that decay through the subnormal
      ! range of a 4-byte real (below 1.2e-38), where every operation takes a microcode assist
      ! and a sweep runs twice as long. They are flushed to zero instead, on every rank alike,
      ! for the whole loop (set here, in the procedure that holds the loop: Fortran restores the
      ! mode a procedure changed when it returns; docs/model.md §1).
      if ((sim%f%arith4 .or. sim%f%half) .and. ieee_support_underflow_control(1.0_sp)) &
        call ieee_set_underflow_mode(gradual=.false.)
      call output_initial(out, sim)
      call checkpoint_start(chk)
      call report_start(prog, sim%step + 1)
      call timer_reset()
      ! a run resumed at its last step has no step left to take: it is finished
      call stop_set(stop, STOP_FINISHED)
      do n = sim%step + 1, lp%steps
        ! the step; what it found that ends the run: a particle out of place (placed) or
        ! faster than run.particle_speed_limit (sim%fast, both checked every step), the
        ! window's end (sim%stopped_early), the last step
        call simulation_step(sim, n, placed)
        call stop_after_step(stop, placed, sim%fast, sim%stopped_early, n == lp%steps)
        t = n*lp%dt
        y0 = 0.0_wp
        if (sim%window_on) y0 = window_offset(sim%win, lp%dx)
        ! the guards, the progress line and the fields read the lattice whole: the step's
        ! interior nodes first (simulation_settle)
        if (reads_lattice()) call simulation_settle(sim)
        call guards()
        ! a failure ends the step here, on every rank at once; the last step's output is the
        ! run's end's (below)
        if (.not. stop%now) call output_and_progress()
        if (.not. stop_failed(stop)) call checkpoints()
        if (stop%now) exit
      end do
      call run_end(run, stop, prog)
    end associate
  contains
    !> Whether the guards, the progress line or the scheduled fields read the lattice after
    !! step n (as guards and output_and_progress decide each of them).
    logical function reads_lattice()
      associate (cfg => run%sim%cfg)
        reads_lattice = guards_due()
        if (cfg%run%progress_every > 0) &
          reads_lattice = reads_lattice .or. mod(n, cfg%run%progress_every) == 0
        reads_lattice = reads_lattice .or. output_reads_lattice(run%sim, n)
      end associate
    end function reads_lattice

    !> Whether the fluid guards check step n: every run.guard_every steps, and after any step
    !! that ends the loop, so that a failed step's message is the guard's when the flow has
    !! become unstable (a free particle leaves the channel only then, and the guard's
    !! diagnosis, where and what to change, is the one to give).
    logical function guards_due()
      guards_due = stop%kind /= STOP_NONE .or. mod(n, run%sim%cfg%run%guard_every) == 0
    end function guards_due

    !> The fluid guards (a non-finite value, the Mach limit) when due; a failure replaces the
    !! step's decision. One part of the time per part (PART_GUARDS).
    subroutine guards()
      character(len=:), allocatable :: failure
      call timer_start(PART_GUARDS)
      if (guards_due()) then
        associate (sim => run%sim, lp => run%sim%lp)
          call guard_check(sim%dom, sim%f, lp%force_lb, sim%cfg%run%mach_limit, n, t, lp%dx, &
                           y0, mach, failure)
        end associate
        if (len(failure) > 0) call stop_set(stop, STOP_GUARD, failure)
      end if
      call timer_stop(PART_GUARDS)
    end subroutine guards

    !> The series, fields and tables on their schedule, then the progress line, which reports
    !! the current Mach number: the guards' of this step, or measured here when they did not
    !! run (a failure then ends the loop as theirs does). One part (PART_OUTPUT): what the
    !! output schedule and run.progress_every cost.
    subroutine output_and_progress()
      character(len=:), allocatable :: failure
      call timer_start(PART_OUTPUT)
      call output_scheduled(run%out, run%sim, n)
      associate (sim => run%sim, lp => run%sim%lp, cfg => run%sim%cfg)
        if (cfg%run%progress_every > 0) then
          if (mod(n, cfg%run%progress_every) == 0) then
            if (mod(n, cfg%run%guard_every) /= 0) then
              call guard_check(sim%dom, sim%f, lp%force_lb, cfg%run%mach_limit, n, t, lp%dx, &
                               y0, mach, failure)
              if (len(failure) > 0) call stop_set(stop, STOP_GUARD, failure)
            end if
            if (.not. stop%now) call report_progress(sim, prog, n, mach)
          end if
        end if
      end associate
      call timer_stop(PART_OUTPUT)
    end subroutine output_and_progress

    !> The checkpoint policy: the clock and signal flags of the step before, a checkpoint when
    !! one is due (on the completed lattice), the flags of this step; a signal or the wall
    !! limit ends the loop after its checkpoint. One part (PART_CHECKPOINTS); the lattice's
    !! completion is the links' part, where simulation_settle counts it.
    subroutine checkpoints()
      logical :: last, writes, interrupted
      last = stop_last(stop)
      call timer_start(PART_CHECKPOINTS)
      call checkpoint_poll(run%chk, run%sim, last, writes)
      if (writes) then
        call timer_stop(PART_CHECKPOINTS)
        call simulation_settle(run%sim)
        call timer_start(PART_CHECKPOINTS)
      end if
      call checkpoint_due(run%chk, run%out, run%sim, last, interrupted)
      if (interrupted) call stop_set(stop, STOP_INTERRUPTED)
      call timer_stop(PART_CHECKPOINTS)
    end subroutine checkpoints
  end subroutine run_execute

  !> How the run ends, as the loop's last decision says (docs/running.md, "When a run
  !! stops"): a failure writes the last step's state, closes the output and stops every rank
  !! with its message; a signal or the wall limit closes the output after its checkpoint; the
  !! last step and the window's end write the output of a finished run.
  subroutine run_end(run, stop, prog)
    type(run_t), intent(inout), asynchronous :: run
    type(stop_t), intent(in) :: stop
    type(progress_t), intent(in) :: prog
    integer :: n
    associate (sim => run%sim, out => run%out, chk => run%chk, lp => run%sim%lp)
      call checkpoint_finish(chk)
      ! whatever ended the loop, what follows writes the lattice of this step
      call simulation_settle(sim)
      n = sim%step
      select case (stop%kind)
      case (STOP_PARTICLE, STOP_GUARD)
        ! every rank saw the same failure: write the last step's state (what went wrong is
        ! in it), close the output, then stop with the message
        if (stop%kind == STOP_PARTICLE) then
          call output_set_stop_reason(out, 'particle: '//stop%message)
        else
          call output_set_stop_reason(out, 'guard: '//stop%message)
        end if
        call log_line('stopped by a guard after step '//itoa(n)//' of '//itoa(lp%steps)// &
                      '; the output holds the run up to this step')
        call output_close(out, sim)
        call fatal_all(stop%message, EXIT_RUNTIME)
      case (STOP_INTERRUPTED)
        ! a signal or the wall limit, after the checkpoint: the output up to this step (a
        ! resumed run cuts back what the checkpoint has not)
        call report_performance(sim, prog, n)
        call checkpoint_stop_message(chk, sim)
        call output_close(out, sim)
      case default
        ! the last step, or the window's end: the output of a finished run
        call report_performance(sim, prog, n)
        if (stop%kind == STOP_WINDOW) then
          call output_set_stop_reason(out, 'window_escape')
          call warn(stop%message)
        else
          call output_set_stop_reason(out, 'finished')
        end if
        call output_final(out, sim)
        call checkpoint_final(chk, out, sim)
        call output_close(out, sim)
        call output_mark_finished(sim)
      end select
    end associate
  end subroutine run_end

  !> Close what is still open and free the lattices and the slab.
  subroutine run_finish(run)
    type(run_t), intent(inout) :: run
    call output_free(run%out)
    call simulation_finish(run%sim)
  end subroutine run_finish

end module dkt_run

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
                                   checkpoint_final, checkpoint_stop_message, &
                                   checkpoint_interrupted, input_check_i, resume_rows
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
    type(lattice_params_t) :: at
    ! a resumed run starts on its checkpoint's lattice, which a window may have grown
    at = lp
    if (len(restart) > 0) at%ny = resume_rows(lp, cfg%window%enabled, restart, comm)
    call simulation_setup(run%sim, cfg, at, comm, lattices=.not. check)
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

  !> The time loop (docs/model.md §1–2): a step of the solver, the guards, then output,
  !! progress and checkpoints, each one call into its own module; and how the run ends.
  subroutine run_execute(run)
    type(run_t), intent(inout), asynchronous :: run
    type(progress_t) :: prog
    integer :: n
    real(wp) :: t, mach, y0
    logical :: last, stop, writes
    character(len=:), allocatable :: failure, placed, fast

    associate (sim => run%sim, out => run%out, chk => run%chk, lp => run%sim%lp, &
               cfg => run%sim%cfg)
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
      failure = ''
      placed = ''
      do n = sim%step + 1, lp%steps
        call simulation_step(sim, n, failure)
        t = n*lp%dt
        y0 = 0.0_wp
        if (sim%window_on) y0 = window_offset(sim%win, lp%dx)
        last = n == lp%steps .or. len(sim%stopped_early) > 0

        ! a particle out of place or a failed guard ends the loop on every rank at once; the
        ! output is written below. A free particle leaves the channel only when the flow has
        ! become unstable, and then the guard's diagnosis (where, what to change) is the one
        ! to give.
        ! the particle speed guard is cheap (one test per particle), so it runs every step
        ! (simulation_step, with the place check; '' when a particle is out of place)
        fast = sim%fast
        ! the guards, the progress line and the fields read the lattice whole: the step's
        ! interior nodes first (simulation_settle)
        if (reads_lattice()) call simulation_settle(sim)
        call timer_start(PART_GUARDS)
        if (len(failure) > 0 .or. len(fast) > 0 .or. mod(n, cfg%run%guard_every) == 0 .or. &
            last) then
          placed = failure
          call guard_check(sim%dom, sim%f, lp%force_lb, cfg%run%mach_limit, n, t, lp%dx, y0, &
                           mach, failure)
          if (len(failure) > 0) exit
          failure = placed
          if (len(failure) > 0) exit
          failure = fast
          if (len(failure) > 0) exit
        end if
        call timer_stop(PART_GUARDS)
        call timer_start(PART_OUTPUT)
        if (.not. last) call output_scheduled(out, sim, n)
        call timer_stop(PART_OUTPUT)
        call timer_start(PART_GUARDS)
        if (cfg%run%progress_every > 0) then
          if (mod(n, cfg%run%progress_every) == 0 .and. .not. last) then
            ! the progress line reports the current Mach number, which the guard measures
            if (mod(n, cfg%run%guard_every) /= 0) then
              call guard_check(sim%dom, sim%f, lp%force_lb, cfg%run%mach_limit, n, t, lp%dx, &
                               y0, mach, failure)
              if (len(failure) > 0) exit
            end if
            call report_progress(sim, prog, n, mach)
          end if
        end if
        call timer_stop(PART_GUARDS)
        call timer_start(PART_CHECKPOINTS)
        call checkpoint_poll(chk, sim, last, writes)
        call timer_stop(PART_CHECKPOINTS)
        if (writes) call simulation_settle(sim)
        call timer_start(PART_CHECKPOINTS)
        call checkpoint_due(chk, out, sim, last, stop)
        call timer_stop(PART_CHECKPOINTS)
        if (stop .or. last) exit
      end do
      call checkpoint_finish(chk)
      ! whatever ended the loop, what follows writes the lattice of this step
      call simulation_settle(sim)
      n = sim%step
      if (len(failure) > 0) then
        ! every rank saw the same failure: write the last step's state (what went wrong is
        ! in it), close the output, then stop with the message
        if (failure == placed) then
          call output_set_stop_reason(out, 'particle: '//failure)
        else
          call output_set_stop_reason(out, 'guard: '//failure)
        end if
        call log_line('stopped by a guard after step '//itoa(n)//' of '//itoa(lp%steps)// &
                      '; the output holds the run up to this step')
        call output_close(out, sim)
        call fatal_all(failure, EXIT_RUNTIME)
      end if
      call report_performance(sim, prog, n)
      if (checkpoint_interrupted(chk)) then
        call checkpoint_stop_message(chk, sim)
        ! the output up to this step; a resumed run cuts back what the checkpoint has not
        call output_close(out, sim)
        return
      end if
      call output_set_stop_reason(out, 'finished')
      if (len(sim%stopped_early) > 0) then
        call output_set_stop_reason(out, 'window_escape')
        call warn(sim%stopped_early)
      end if
      call output_final(out, sim)
      call checkpoint_final(chk, out, sim)
      call output_close(out, sim)
      call output_mark_finished(sim)
    end associate
  contains
    !> Whether the guards, the progress line or the scheduled fields read the lattice after
    !! step n (as the loop decides each of them below).
    logical function reads_lattice()
      associate (cfg => run%sim%cfg)
        reads_lattice = len(failure) > 0 .or. len(fast) > 0 .or. &
                        mod(n, cfg%run%guard_every) == 0 .or. last
        if (cfg%run%progress_every > 0) &
          reads_lattice = reads_lattice .or. mod(n, cfg%run%progress_every) == 0
        reads_lattice = reads_lattice .or. output_reads_lattice(run%sim, n)
      end associate
    end function reads_lattice
  end subroutine run_execute

  !> Close what is still open and free the lattices and the slab.
  subroutine run_finish(run)
    type(run_t), intent(inout) :: run
    call output_free(run%out)
    call simulation_finish(run%sim)
  end subroutine run_finish

end module dkt_run

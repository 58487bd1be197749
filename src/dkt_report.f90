!> What the run tells its user on the log: the start-up summary (derived lattice, sizes,
!> memory, models, output), a progress line now and then, and the performance at the end.
module dkt_report
  use mpi_f08, only: MPI_Wtime, MPI_Allreduce, MPI_SUM, MPI_MAX, MPI_IN_PLACE, MPI_INTEGER8
  use dkt_kinds, only: wp, i8, MPI_WP
  use dkt_errors, only: warn
  use dkt_mrt, only: collision_describe
  use dkt_diagnostics, only: SQ_UNDAMPED
  use dkt_log, only: log_line
  use dkt_memory, only: rank_memory, fixed2, MIB
  use dkt_store, only: lattice_bytes
  use dkt_domain, only: domain_t, domain_resize
  use dkt_choices, only: STREAMING_IN_PLACE, END_VELOCITY, FLOW_REST, PRECISION_HALF, &
                         PRESSURE_HYDROSTATIC
  use dkt_text, only: itoa, counted
  use dkt_version, only: dkt_version_string, dkt_git_revision
  use dkt_run_state, only: simulation_t
  use dkt_timers, only: timer_seconds, timer_name, N_PARTS, wait_seconds
  use dkt_particles, only: particles_messages, particles_work
  use dkt_links, only: links_count, links_work
  implicit none
  private
  public :: progress_t, report_summary, report_start, report_progress, report_performance

  !> the clock of the progress lines and of the performance line
  type :: progress_t
    integer :: first = 1        !! the first step of this process (a resumed run starts later)
    integer :: last = 0         !! the step of the last progress line
    real(wp) :: t_start = 0.0_wp !! wall time at the first step
    real(wp) :: t_last = 0.0_wp  !! wall time of the last progress line
    integer(i8) :: updates_last = 0 !! simulation_t updates at the last progress line
  end type progress_t

  !> the slowest lattice velocity scale at which 'half' was measured to give the answers of
  !! 4-byte storage (docs/tradeoff.md): below it a run in 'half' is warned about
  real(wp), parameter :: HALF_SLOWEST = 1.0e-2_wp

contains

  !> The derived lattice parameters, sizes and models of the run, printed by rank 0 before it
  !! starts (and by --check instead of running).
  subroutine report_summary(sim)
    type(simulation_t), intent(in) :: sim
    character(len=512) :: line
    character(len=256) :: particles
    character(len=400) :: window
    real(wp) :: s(0:8), mem(3)
    integer :: k
    type(domain_t) :: largest
    character(len=:), allocatable :: grown
    associate (lp => sim%lp, cfg => sim%cfg, dom => sim%dom)
      call log_line('dktlbm '//dkt_version_string//' ('//dkt_git_revision//')')
      line = 'scene '//trim(cfg%file)//' on '//counted(dom%nranks, 'rank')
      call log_line(trim(line))
      write (line, '(a,es12.5,a,es12.5,a,f8.5,a,es12.5)') 'lattice: dx = ', lp%dx, ' cm, dt = ', &
        lp%dt, ' s, tau = ', lp%tau, ', nu = ', lp%nu_lb
      call log_line(trim(line)//' (lattice units)')
      s = collision_describe(sim%coll)
      write (line, '(a,9(1x,f7.4))') 'rates s_0..s_8 (rho e eps jx qx jy qy pxx pxy):', s
      call log_line(trim(line))
      write (line, '(a,es12.4e3,a,es12.4e3,a,es12.4e3)') 'velocity scale ', &
        lp%u_scale_lb*lp%dx/lp%dt, ' cm/s: expected max Mach ', lp%mach, ', Reynolds ', lp%reynolds
      call log_line(trim(line))
      ! the weakly compressible error is O(Ma^2) (docs/model.md §1, "Mach-aware set-up")
      ! (three exponent digits only when two cannot hold it: '**********' otherwise)
      if (abs(lp%mach) < 1.0e49_wp .and. abs(lp%mach) > 1.0e-49_wp) then
        write (line, '(a,es10.3e2,a)') 'compressibility: Ma^2 = ', lp%mach**2, ', error class '
      else
        write (line, '(a,es11.3e3,a)') 'compressibility: Ma^2 = ', lp%mach**2, ', error class '
      end if
      line = trim(line)//' '//lp%compressibility
      if (cfg%lbm%mach > 0.0_wp) then
        write (line, '(a,f8.5,a,es10.3e2,a)') trim(line)//'; tau = ', lp%tau, &
          ' from lbm.mach = ', cfg%lbm%mach, ' (acoustic scaling; lbm.tau not used)'
      end if
      call log_line(trim(line))
      if (allocated(sim%substep_note)) then
        if (len(sim%substep_note) > 0) call log_line('note: '//sim%substep_note)
      end if
      if (sim%particles_move .and. .not. sim%coll%bgk .and. sim%coll%s_q < SQ_UNDAMPED) then
        ! SQ_UNDAMPED: the Uhlmann DKT pair at tau = 0.512-0.53 (E3 s_q = 0.05-0.23) blew up at
        ! 20, 30 and 40 spacings per diameter; with s_q = 1.2 it ran through
        write (line, '(a,f6.3,a,f6.4,a)') 'the heat-flux rate s_q = ', sim%coll%s_q, &
          ' (tau = ', lp%tau, ') leaves the q moments almost undamped; with moving '// &
          'particles such runs were measured unstable. Set lbm.s_q = 1.2 (walls then sit '// &
          'slightly off half-way), or raise lbm.tau'
        call warn(trim(line))
      end if
      if (cfg%lbm%precision_kind == PRECISION_HALF .and. lp%u_scale_lb < HALF_SLOWEST) then
        ! docs/tradeoff.md, "Populations in 2 bytes": at lattice speeds near 1e-4 the
        ! deviations f_i - w_i fall to the 16-bit format's subnormal spacing
        write (line, '(a,es10.3e2)') 'lbm.precision = ''half'' is accurate only where the '// &
          'flow moves at lattice velocities of 1e-2 or more; this scene''s velocity scale is ', &
          lp%u_scale_lb
        call warn(trim(line)//' (from '//lp%velocity_source//'), where 16-bit populations '// &
                  'were measured 14-20 % off. Use lbm.precision = ''single_arith'' '// &
                  '(docs/tradeoff.md)')
      end if
      if (lp%mach > cfg%run%mach_limit) then
        write (line, '(a,es12.4e3,a,es12.4e3,a)') 'the expected Mach number ', lp%mach, &
          ' exceeds run.mach_limit = ', cfg%run%mach_limit, '; the guard will stop the run. '
        call warn(trim(line)//' The velocity scale comes from '// &
                  lp%velocity_source//': lower it, or '//lp%dx_knob// &
                  ' or lower lbm.tau (both shrink dt)')
      end if
      write (line, '(a,i0,a,i0,a,i0,a,i0,a,i0,a)') 'cells ', lp%nx, ' x ', dom%ny, ' = ', &
        int(lp%nx, i8)*dom%ny, ', steps ', lp%steps, ', rows per rank ', dom%nyl, ' (rank 0)'
      call log_line(trim(line))
      mem = rank_memory(cfg, lp, dom%nxp, dom%nyl)/MIB
      grown = ''
      if (lp%ny_max > dom%ny) then
        ! a window that may grow (window.max_above): what rank 0 holds at its largest, the
        ! figure the memory check (dkt_memory) took
        largest = dom
        call domain_resize(largest, lp%ny_max)
        grown = ' (up to '//fixed2(sum(rank_memory(cfg, lp, largest%nxp, largest%nyl))/MIB)// &
                ' MiB in all once the window has grown to '//itoa(lp%ny_max)//' rows)'
      end if
      if (sim%particles_on) then
        write (particles, '(a,i0,a,i0,a)') 'particles: ', sim%parts%ntotal, ' (', &
          links_count(sim%links), ' boundary links on rank 0)'
      else
        particles = 'particles: none'
      end if
      window = 'window: none'
      if (sim%window_on) then
        write (window, '(a,f8.3,a,f6.1,a,f6.1,a,f8.3,a)') 'window: ', dom%ny*lp%dx, ' cm (', &
          cfg%window%below, ' + ', cfg%window%above, ' D_1) from y = ', sim%win%y_origin, ' cm'
        if (lp%ny_max > dom%ny) then
          write (window, '(a,a,f0.1,a)') trim(window), ', grows to at most ', &
            lp%ny_max*lp%dx/lp%largest_diameter - cfg%window%below, ' D_1 above'
          if (cfg%window%max_above < 0.0_wp) then
            window = trim(window)//' (window.max_above = -1: window.above and the velocity '// &
                     'scale times the run''s length)'
          end if
        else
          window = trim(window)//', never grows (window.max_above = 0)'
        end if
      end if
      line = 'memory per rank: lattices '//fixed2(mem(1))//' MiB ('// &
             trim(merge('one lattice, streamed in place', 'two lattices                  ', &
                        cfg%lbm%streaming_kind == STREAMING_IN_PLACE))// &
             '; populations stored in '//itoa(lattice_bytes(cfg%lbm%precision_kind))// &
             trim(merge(' bytes (16 bits: 1 sign, 4 exponent, 11 mantissa)', &
                        ' bytes                                           ', &
                        cfg%lbm%precision_kind == PRECISION_HALF))//', lbm.precision = '// &
             trim(cfg%lbm%precision)//'), particle arrays '// &
             fixed2(mem(2))//' MiB, output buffers '//fixed2(mem(3))//' MiB while writing'// &
             grown//'; '//trim(particles)//'; '//trim(window)
      call log_line(trim(line))
      line = 'models: '//merge('BGK (E4)        ', 'MRT (E1-E3)     ', sim%coll%bgk)
      line = trim(line)//', sides '//trim(cfg%domain%sides)//', lower end '// &
             trim(cfg%domain%lower)//', upper end '//trim(cfg%domain%upper)
      if (sim%coll%forced) line = trim(line)//', body force'
      if (any([cfg%domain%lower_kind, cfg%domain%upper_kind] == END_VELOCITY)) &
        line = trim(line)//', inlet '//trim(cfg%inlet%profile)
      if (cfg%initial%flow_kind /= FLOW_REST) &
        line = trim(line)//', initial '//trim(cfg%initial%flow)
      if (cfg%initial%pressure_kind == PRESSURE_HYDROSTATIC) &
        line = trim(line)//', initial pressure hydrostatic'
      if (sim%particles_on) then
        line = trim(line)//'; particles on (E6 '//trim(cfg%coupling%bounce_back)// &
               ', E7 '//trim(cfg%coupling%momentum)//', interior '// &
               trim(cfg%coupling%interior)//', E8-E11'
        if (cfg%coupling%average_force) line = trim(line)//', E8 force averaged over two steps'
        line = trim(line)//')'
      else
        line = trim(line)//'; particles off'
      end if
      if (sim%window_on) then
        line = trim(line)//'; window on (lower end fluid at rest, upper end outflow)'
      else
        line = trim(line)//'; window off'
      end if
      call log_line(trim(line))
      if (sim%pair_on) then
        write (line, '(a,f6.2,a,f6.2,a)') 'pair diagnostics: particles 1 and 2; a kissing '// &
          'episode starts at D_r <= ', sim%pair%enter, ' spacings and ends at D_r > ', &
          sim%pair%release, ' spacings'
        call log_line(trim(line))
      end if
      k = lp%field_every
      if (k > 0) then
        line = 'fields every '//counted(k, 'step')//' and at the end'
      else
        line = 'fields at the end'
      end if
      call log_line(trim(line)//' into '//cfg%output_dir//'/'//cfg%name//'.h5')
    end associate
  end subroutine report_summary

  !> Start the clock before step `first`.
  subroutine report_start(prog, first)
    type(progress_t), intent(out) :: prog
    integer, intent(in) :: first
    prog%first = first
    prog%last = first - 1
    prog%t_start = MPI_Wtime()
    prog%t_last = prog%t_start
  end subroutine report_start

  !> A progress line after step n: time, t*, the Mach number `mach` the guard measured, the
  !! speed since the last line and the time the remaining steps will take at this pace.
  subroutine report_progress(sim, prog, n, mach)
    type(simulation_t), intent(in) :: sim
    type(progress_t), intent(inout) :: prog
    integer, intent(in) :: n
    real(wp), intent(in) :: mach
    real(wp) :: now, mlups, eta
    integer :: h, m, s
    character(len=256) :: line
    now = MPI_Wtime()
    mlups = real(sim%updates - prog%updates_last, wp)/max(now - prog%t_last, 1.0e-9_wp)/1.0e6_wp
    ! the time per step of this process (a resumed run started at step first - 1)
    eta = (now - prog%t_start)/real(n - prog%first + 1, wp)*real(sim%lp%steps - n, wp)
    h = int(eta)/3600
    m = mod(int(eta), 3600)/60
    s = mod(int(eta), 60)
    write (line, '(a,i0,a,i0,a,es11.4,a,f9.4,a,f7.4,a,f9.2,a,i0,a,i2.2,a,i2.2)') 'step ', n, &
      '/', sim%lp%steps, '  t = ', n*sim%lp%dt, ' s  t* = ', n*sim%lp%dt/sim%cfg%run%t_ref, &
      '  Ma = ', mach, '  MLUPS ', mlups, '  ETA ', h, ':', m, ':', s
    call log_line(trim(line))
    prog%last = n
    prog%t_last = now
    prog%updates_last = sim%updates
  end subroutine report_progress

  !> The speed of this process's steps, up to step n, in million lattice updates per second.
  subroutine report_performance(sim, prog, n)
    type(simulation_t), intent(in) :: sim
    type(progress_t), intent(in) :: prog
    integer, intent(in) :: n
    real(wp) :: t
    character(len=256) :: line
    t = MPI_Wtime() - prog%t_start
    write (line, '(a,f9.2,a,i0,a,a,a,f9.3,a)') 'performance: ', &
      real(sim%updates, wp)/max(t, 1.0e-9_wp)/1.0e6_wp, ' MLUPS (', &
      int(sim%lp%nx, i8)*sim%dom%ny, ' cells x ', &
      counted(n - prog%first + 1, 'step'), ' in ', t, ' s on '
    call log_line(trim(line)//' '//counted(sim%dom%nranks, 'rank')//')')
    call report_parts(sim, t, n - prog%first + 1)
    if (sim%particles_on) call report_messages(sim, n - prog%first + 1)
  end subroutine report_performance

  !> The `particle messages` line: the MPI calls the particles made per step, to neighbouring
  !! slabs and collectives, the most of any rank (docs/design.md, "Particles across slabs");
  !! output and checkpoints, which may gather, are not counted.
  subroutine report_messages(sim, steps)
    type(simulation_t), intent(in) :: sim
    integer, intent(in) :: steps
    integer(i8) :: calls(2)
    character(len=160) :: line
    calls = particles_messages(sim%parts)
    call MPI_Allreduce(MPI_IN_PLACE, calls, 2, MPI_INTEGER8, MPI_MAX, sim%dom%comm)
    write (line, '(a,f0.2,a,f0.2,a,i0,a)') 'particle messages per step: ', &
      real(calls(1), wp)/max(steps, 1), ' messages to neighbouring slabs, ', &
      real(calls(2), wp)/max(steps, 1), ' collectives (the most of any rank; ', &
      sim%parts%ntotal, ' particles)'
    call log_line(trim(line))
    call report_work(sim, steps)
  end subroutine report_messages

  !> The `work per step` line, each figure the most of any rank: the cells of a slab, the
  !! boundary links of a search and the interior nodes of a reset (means over the run), the
  !! particles held at the end with the contact sub-steps of a step, and the bytes sent to
  !! neighbouring slabs per step. docs/performance.md ("A cost model") prices each.
  subroutine report_work(sim, steps)
    type(simulation_t), intent(in) :: sim
    integer, intent(in) :: steps
    real(wp) :: work(5)
    character(len=240) :: line
    work([1, 4]) = particles_work(sim%parts, steps)
    work(2:3) = links_work(sim%links)
    work(5) = real(sim%dom%nx, wp)*sim%dom%nyl
    call MPI_Allreduce(MPI_IN_PLACE, work, 5, MPI_WP, MPI_MAX, sim%dom%comm)
    write (line, '(a,i0,a,i0,a,i0,a,i0,a,i0,a,i0,a)') 'work per step: ', nint(work(5), i8), &
      ' cells, ', nint(work(2), i8), ' boundary links, ', nint(work(3), i8), &
      ' interior nodes, ', nint(work(4), i8), ' particles held x ', sim%parts%substeps, &
      ' sub-steps, ', nint(work(1), i8), ' bytes to neighbouring slabs (the most of any rank)'
    call log_line(trim(line))
  end subroutine report_work

  !> The `time per part` line: each part's share of the loop's wall time t, the mean over the
  !! ranks (dkt_timers says what each part holds; `other` is the rest: the step counters, the
  !! loop itself). A rank that waits for a neighbour's halo counts the wait in `flow`. On more
  !! than one rank, the `busy per step` line: each rank's loop less its waits for the others,
  !! per step of the `steps` timed, the slowest, the fastest and the mean (the slabs' balance).
  subroutine report_parts(sim, t, steps)
    type(simulation_t), intent(in) :: sim
    real(wp), intent(in) :: t
    integer, intent(in) :: steps
    real(wp) :: share(N_PARTS + 1), busy(2), mine, mean
    character(len=:), allocatable :: line
    integer :: k
    ! each rank's shares of its own loop time, then their mean
    share(1:N_PARTS) = 100.0_wp*timer_seconds()/max(t, 1.0e-9_wp)
    share(N_PARTS + 1) = max(100.0_wp - sum(share(1:N_PARTS)), 0.0_wp)
    call MPI_Allreduce(MPI_IN_PLACE, share, N_PARTS + 1, MPI_WP, MPI_SUM, sim%dom%comm)
    share = share/sim%dom%nranks
    line = 'time per part:'
    do k = 1, N_PARTS
      line = line//' '//timer_name(k)//' '//fixed(share(k), 1)//' %,'
    end do
    call log_line(line//' other '//fixed(share(N_PARTS + 1), 1)//' % (mean over '// &
                  counted(sim%dom%nranks, 'rank')//')')
    ! each rank's busy time: the loop's less its waits for the others (the slabs' balance);
    ! the largest and the smallest (as the largest of its negative), then the sum
    if (sim%dom%nranks > 1 .and. steps > 0) then
      mine = max(t - wait_seconds(), 0.0_wp)
      busy = [mine, -mine]
      call MPI_Allreduce(MPI_IN_PLACE, busy, 2, MPI_WP, MPI_MAX, sim%dom%comm)
      call MPI_Allreduce(mine, mean, 1, MPI_WP, MPI_SUM, sim%dom%comm)
      mean = mean/sim%dom%nranks
      call log_line('busy per step (the loop less the waits for other ranks): slowest rank '// &
                    fixed(1.0e3_wp*busy(1)/steps, 3)//' ms, fastest '// &
                    fixed(-1.0e3_wp*busy(2)/steps, 3)//' ms, mean '// &
                    fixed(1.0e3_wp*mean/steps, 3)//' ms; slowest over mean '// &
                    fixed(busy(1)/max(mean, 1.0e-12_wp), 2))
    end if
  end subroutine report_parts

  !> x with `digits` decimals (a leading 0 before the point).
  function fixed(x, digits) result(s)
    real(wp), intent(in) :: x
    integer, intent(in) :: digits
    character(len=:), allocatable :: s
    character(len=32) :: buf
    character(len=8) :: form
    write (form, '(a,i0,a)') '(f0.', digits, ')'
    write (buf, form) x
    s = trim(buf)
    if (s(1:1) == '.') s = '0'//s
  end function fixed

end module dkt_report

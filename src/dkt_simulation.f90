!> A flow simulation on MPI slabs: set-up from the configuration, the time loop, output.
!> The time loop (simulation_run) reads like docs/model.md §1–2: exchange, boundary ghosts, fused
!> stream–collide, open ends, guards, output.
module dkt_simulation
  use mpi_f08, only: MPI_Comm, MPI_Wtime, MPI_Bcast, MPI_LOGICAL, MPI_Comm_size, &
                     MPI_Iallreduce, MPI_Wait, MPI_Request, MPI_STATUS_IGNORE, MPI_INTEGER, &
                     MPI_BOR, MPI_Allreduce, MPI_MAX, MPI_Comm_split_type, &
                     MPI_COMM_TYPE_SHARED, MPI_INFO_NULL, MPI_Comm_free, MPI_IN_PLACE
  use iso_fortran_env, only: compiler_version
  use dkt_kinds, only: wp, i8, pi, cs2, mpi_wp
  use dkt_errors, only: fatal_all, fatal_local, warn, EXIT_RUNTIME
  use dkt_config, only: config_t, lattice_params_t, config_output_dir, window_bottom, &
                        config_to_namelist, kiss_thresholds, kiss_enter_cells, &
                        velocity_scale_source, dx_knob
  use dkt_lattice, only: equilibrium
  use dkt_mrt, only: collision_t, collision_init, collision_describe, stream_collide
  use dkt_domain, only: domain_t, domain_init, domain_free, halo_start, halo_finish, &
                        MIN_SLAB_ROWS
  use dkt_boundary, only: boundary_t, boundary_init, fill_local_ghosts, fill_halo_ghosts, &
                          apply_open_ends, END_WALL, END_PERIODIC, END_VELOCITY, END_OUTFLOW
  use dkt_fields, only: macroscopic, vorticity
  use dkt_particles, only: particles_t, particles_init, particles_find_links, particles_bounce, &
                           particles_interior, particles_reduce_forces, particles_move, &
                           particles_solid_field, particles_stable_substeps, MOTION_FREE, &
                           MOTION_FIXED, &
                           MOTION_PRESCRIBED, BB_HALFWAY, BB_YU, BB_BFL
  use dkt_diagnostics, only: guard_check, guard_set_advice, pair_diag_t, pair_diag_init, &
                             pair_diag_update, pair_pattern, pair_gaps, drag_coefficient
  use dkt_window, only: window_t, window_init, window_offset, window_follow, window_escaped
  use dkt_checkpoint, only: checkpoint_t, checkpoint_write, checkpoint_read, checkpoint_name, &
                            NSTATE
  use dkt_signals, only: signals_install, signal_caught, SIGTERM
  use dkt_io, only: io_t, io_open, io_write_run, io_write_fields, io_close, io_write_series, &
                    io_write_table, io_write_attribute, io_reopen
  use dkt_log, only: log_line, log_open, log_close
  use dkt_filesystem, only: remove_file, write_marker
  use dkt_run_state, only: simulation_t, path_t
  use dkt_output, only: output_fields, output_particles, output_pair_report, output_close, &
                        output_fail
  use dkt_registry, only: itoa, fmt_real
  use dkt_version, only: dkt_version_string, dkt_git_revision, dkt_build_flags
  implicit none
  private
  public :: simulation_t, simulation_setup, simulation_summary, simulation_run, &
            simulation_finish, simulation_restore

  real(wp), parameter :: GIB = 2.0_wp**30, MIB = 2.0_wp**20

contains

  integer function end_kind(name)
    character(len=*), intent(in) :: name
    select case (trim(name))
    case ('periodic'); end_kind = END_PERIODIC
    case ('velocity'); end_kind = END_VELOCITY
    case ('outflow'); end_kind = END_OUTFLOW
    case default; end_kind = END_WALL
    end select
  end function end_kind

  !> Decompose, check that the memory the run needs is there, allocate the two lattices and
  !! set the initial state. Every rank calls it; a decomposition that cannot work stops all
  !! ranks with the largest rank count that does, a run that needs more memory than a node
  !! gives stops them before anything large is allocated. `lattices` = .false. (--check) sets
  !! up everything the start-up report needs but allocates no lattice.
  subroutine simulation_setup(sim, cfg, lp, comm, lattices)
    type(simulation_t), intent(inout) :: sim
    type(config_t), intent(in) :: cfg
    type(lattice_params_t), intent(in) :: lp
    type(MPI_Comm), intent(in) :: comm
    logical, intent(in), optional :: lattices
    logical :: with_lattices
    character(len=:), allocatable :: err
    logical :: periodic_x, periodic_y
    integer :: min_rows
    real(wp) :: enter, release

    sim%cfg = cfg
    sim%lp = lp
    periodic_x = cfg%domain%sides == 'periodic'
    periodic_y = cfg%domain%lower == 'periodic'
    sim%particles_on = lp%particles_on
    min_rows = MIN_SLAB_ROWS
    if (sim%particles_on) then
      ! a slab holds at least the largest particle plus its interpolation stencil
      min_rows = max(min_rows, ceiling(maxval(cfg%particles%diameter(1:cfg%particles%count)) &
                                       /lp%dx) + 4)
    end if
    call domain_init(sim%dom, comm, lp%nx, lp%ny, periodic_x, periodic_y, min_rows, err)
    if (len(err) > 0) call fatal_all(trim(cfg%file)//': '//err)
    call check_memory(sim)
    with_lattices = .true.
    if (present(lattices)) with_lattices = lattices
    call boundary_init(sim%bc, periodic_x, end_kind(cfg%domain%lower), &
                       end_kind(cfg%domain%upper), lp%u_in_lb, cfg%inlet%profile == 'parabolic', &
                       cfg%inlet%ramp_time/lp%dt)
    call collision_init(sim%coll, lp%s, cfg%lbm%collision == 'bgk', lp%force_lb)
    if (with_lattices) then
      allocate (sim%f(0:sim%dom%nxp - 1, 0:sim%dom%nyl + 1, 0:8))
      allocate (sim%f_next(0:sim%dom%nxp - 1, 0:sim%dom%nyl + 1, 0:8))
      call initialise(sim)
    end if
    ! the guards' advice names the knob that sets dx in this scene
    call guard_set_advice(dx_knob(cfg))
    sim%window_on = cfg%window%enabled
    if (sim%window_on) then
      associate (d1 => maxval(cfg%particles%diameter(1:cfg%particles%count))/lp%dx)
        call window_init(sim%win, window_bottom(cfg), cfg%window%below*d1, cfg%window%margin*d1)
      end associate
    end if
    if (sim%particles_on) call setup_particles(sim)
    sim%pair_on = cfg%particles%count >= 2
    if (sim%pair_on) then
      call kiss_thresholds(cfg, enter, release)
      call pair_diag_init(sim%pair, enter, release)
    end if
    sim%stopped_early = ''
  end subroutine simulation_setup

  !> Bytes one rank needs for its slab, the one formula behind the start-up report and the
  !! memory check: (1) the two lattices f and f_next, 9 doubles per padded node (nxp columns,
  !! nyl rows and two halo rows); (2) the particles: per-row force sums (3 doubles per row and
  !! particle) and the boundary links, at most 8 per surface node and about pi d + 8 surface
  !! nodes per particle of d spacings (28 bytes a link); (3) the output: the field buffer of
  !! up to 6 doubles per node, the halo send and receive buffers (12 doubles per column).
  pure function rank_memory(cfg, lp, nxp, nyl) result(bytes)
    type(config_t), intent(in) :: cfg
    type(lattice_params_t), intent(in) :: lp
    integer, intent(in) :: nxp, nyl
    real(wp) :: bytes(3)
    real(wp) :: d_cells
    integer :: n
    bytes(1) = 2.0_wp*9.0_wp*8.0_wp*real(nxp, wp)*real(nyl + 2, wp)
    n = cfg%particles%count
    bytes(2) = 0.0_wp
    if (n > 0) then
      d_cells = maxval(cfg%particles%diameter(1:n))/lp%dx
      bytes(2) = real(n, wp)*(3.0_wp*8.0_wp*real(nyl, wp) + 28.0_wp*8.0_wp*(pi*d_cells + 8.0_wp))
    end if
    bytes(3) = 6.0_wp*8.0_wp*real(lp%nx, wp)*real(nyl, wp) + 12.0_wp*8.0_wp*real(lp%nx, wp)
  end function rank_memory

  !> Stop every rank before the lattices are allocated when the ranks of one node would need
  !! more than it gives: run.memory_limit GiB, or (0) MemAvailable of /proc/meminfo on rank 0's
  !! node. A node holds at most the largest count of ranks sharing one node; each rank is
  !! counted with the largest slab. Without /proc/meminfo and with no limit, nothing is checked.
  subroutine check_memory(sim)
    type(simulation_t), intent(inout) :: sim
    type(MPI_Comm) :: node
    real(wp) :: bytes(3), need, avail, limit
    integer :: node_ranks
    character(len=:), allocatable :: source
    character(len=160) :: msg
    bytes = rank_memory(sim%cfg, sim%lp, sim%dom%nxp, sim%dom%nyl)
    call MPI_Allreduce(MPI_IN_PLACE, bytes, 3, mpi_wp, MPI_MAX, sim%dom%comm)
    call MPI_Comm_split_type(sim%dom%comm, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, node)
    call MPI_Comm_size(node, node_ranks)
    call MPI_Comm_free(node)
    call MPI_Allreduce(MPI_IN_PLACE, node_ranks, 1, MPI_INTEGER, MPI_MAX, sim%dom%comm)
    avail = -1.0_wp
    if (sim%dom%rank == 0) avail = mem_available()
    call MPI_Bcast(avail, 1, mpi_wp, 0, sim%dom%comm)
    if (sim%cfg%run%memory_limit > 0.0_wp) then
      limit = sim%cfg%run%memory_limit*GIB
      source = 'run.memory_limit'
    else
      limit = avail
      source = 'MemAvailable in /proc/meminfo'
    end if
    need = real(node_ranks, wp)*sum(bytes)
    if (limit < 0.0_wp .or. need <= limit) return
    write (msg, '(a,i0,a,i0,a,i0,a)') ' for ', sim%lp%nx, ' x ', sim%lp%ny, &
      ' cells, times ', node_ranks, ' ranks on a node = '
    call fatal_all(trim(sim%cfg%file)//': the run needs '//fixed2(sum(bytes)/GIB)// &
                   ' GiB per rank (lattices '//fixed2(bytes(1)/GIB)//' GiB, particle arrays '// &
                   fixed2(bytes(2)/GIB)//' GiB, output buffers '//fixed2(bytes(3)/GIB)// &
                   ' GiB)'//trim(msg)//' '//fixed2(need/GIB)//' GiB, more than the '// &
                   fixed2(limit/GIB)//' GiB allowed ('//source//'); use fewer '// &
                   'cells: a larger lbm.dx, a smaller lbm.cells_per_diameter (it sets dx '// &
                   'from the smallest particle; with &pair a smaller gamma) or a smaller '// &
                   '&domain; or spread the ranks over more nodes; or set run.memory_limit '// &
                   '(GiB) to what the run may really use')
  end subroutine check_memory

  !> x rounded to two decimals, as text ('0.05', '335.32')
  function fixed2(x) result(s)
    real(wp), intent(in) :: x
    character(len=:), allocatable :: s
    s = fmt_real(anint(x*100.0_wp)/100.0_wp)
  end function fixed2

  !> MemAvailable of /proc/meminfo in bytes; -1 where it cannot be read.
  function mem_available() result(bytes)
    real(wp) :: bytes
    character(len=256) :: line
    integer :: u, ios
    real(wp) :: kib
    bytes = -1.0_wp
    open (newunit=u, file='/proc/meminfo', status='old', action='read', iostat=ios)
    if (ios /= 0) return
    do
      read (u, '(a)', iostat=ios) line
      if (ios /= 0) exit
      if (index(line, 'MemAvailable:') == 1) then
        read (line(14:), *, iostat=ios) kib
        if (ios == 0) bytes = kib*1024.0_wp
        exit
      end if
    end do
    close (u)
  end function mem_available

  !> The particles of the scene in lattice units (docs/model.md §3–4), their first boundary links
  !! and the fluid inside them set to their velocity.
  subroutine setup_particles(sim)
    type(simulation_t), intent(inout) :: sim
    integer :: n, k
    integer, allocatable :: motion(:)
    real(wp) :: dx, dt, rho_f, y0
    integer :: scheme
    character(len=256) :: line
    n = sim%cfg%particles%count
    dx = sim%lp%dx
    dt = sim%lp%dt
    rho_f = sim%cfg%fluid%density
    allocate (motion(n))
    do k = 1, n
      select case (trim(sim%cfg%particles%motion(k)))
      case ('fixed'); motion(k) = MOTION_FIXED
      case ('prescribed'); motion(k) = MOTION_PRESCRIBED
      case default; motion(k) = MOTION_FREE
      end select
    end do
    select case (trim(sim%cfg%coupling%bounce_back))
    case ('halfway'); scheme = BB_HALFWAY
    case ('bfl'); scheme = BB_BFL
    case default; scheme = BB_YU
    end select
    y0 = 0.0_wp
    if (sim%window_on) y0 = sim%win%y_origin ! positions are absolute, rows count from here
    associate (p => sim%cfg%particles, c => sim%cfg%collision)
      ! E10 stiffnesses: eps_p in cm^2 s^2/(g/cm) and eps'_p in cm s^2/(g/cm) per unit depth
      call particles_init(sim%parts, sim%dom, p%x(1:n)/dx, (p%y(1:n) - y0)/dx, &
                          0.5_wp*p%diameter(1:n)/dx, &
                          p%u(1:n)*dt/dx, p%v(1:n)*dt/dx, p%omega(1:n)*dt, &
                          p%density(1:n)/rho_f, motion, scheme, &
                          sim%cfg%coupling%momentum == 'galilean', p%gravity*dt*dt/dx, &
                          c%stiffness*rho_f/dt**2, c%stiffness_overlap*rho_f*dx/dt**2, c%range, &
                          c%substeps)
    end associate
    sim%particles_move = any(motion /= MOTION_FIXED)
    ! docs/model.md §4: a stiff contact law is sub-stepped, not softened, and the log says so
    if (particles_stable_substeps(sim%parts) > sim%parts%substeps) then
      write (line, '(a,i0,a,i0,a)') 'collision stiffness: the explicit particle update needs ', &
        particles_stable_substeps(sim%parts), ' sub-steps per fluid step to stay stable; '// &
        'using them instead of collision.substeps = ', sim%parts%substeps, &
        ' (the contact law is unchanged)'
      sim%parts%substeps = particles_stable_substeps(sim%parts)
      call log_line(trim(line))
    end if
    call particles_find_links(sim%parts, sim%dom)
    if (associated(sim%f)) call particles_interior(sim%parts, sim%dom, sim%f)
  end subroutine setup_particles

  !> Initial populations: equilibrium of the initial flow (post-collision state at t = 0).
  subroutine initialise(sim)
    type(simulation_t), intent(inout) :: sim
    integer :: x, j, jg
    real(wp) :: kx, ky, u0, xc, yc, ux, uy, p
    ! first touch of every entry, ghosts and padding included, so no garbage is ever read
    sim%f = 0.0_wp
    sim%f_next = 0.0_wp
    select case (trim(sim%cfg%initial%flow))
    case ('taylor_green')
      ! u = U(-cos kx sin ky, sin kx cos ky), p = -U^2/4 (cos 2kx + cos 2ky) (lattice units)
      kx = 2.0_wp*pi/real(sim%lp%nx, wp)
      ky = 2.0_wp*pi/real(sim%lp%ny, wp)
      u0 = sim%lp%u_init_lb
      do j = 1, sim%dom%nyl
        jg = sim%dom%y0 + j
        do x = 1, sim%lp%nx
          xc = real(x, wp) - 0.5_wp
          yc = real(jg, wp) - 0.5_wp
          ux = -u0*cos(kx*xc)*sin(ky*yc)
          uy = u0*sin(kx*xc)*cos(ky*yc)
          p = -0.25_wp*u0*u0*(cos(2.0_wp*kx*xc) + cos(2.0_wp*ky*yc))
          sim%f(x, j, :) = equilibrium(1.0_wp + p/cs2, ux, uy)
        end do
      end do
    case default
      do j = 1, sim%dom%nyl
        do x = 1, sim%lp%nx
          sim%f(x, j, :) = equilibrium(1.0_wp, 0.0_wp, 0.0_wp)
        end do
      end do
    end select
  end subroutine initialise

  !> Continue from the checkpoint at `path` (written by this scene on any number of ranks): the
  !! populations, the particles, the window, the kissing episodes and the step. A checkpoint of
  !! another lattice or time step, or with another number of particles, stops every rank.
  subroutine simulation_restore(sim, path)
    type(simulation_t), intent(inout) :: sim
    character(len=*), intent(in) :: path
    type(checkpoint_t) :: chk
    character(len=:), allocatable :: err
    character(len=512) :: msg
    integer :: k
    call checkpoint_read(path, sim%dom%comm, sim%f, sim%lp%nx, sim%lp%ny, sim%dom%nyl, &
                         sim%dom%y0, merge(sim%parts%n, 0, sim%particles_on), chk, err)
    if (len(err) > 0) call fatal_all('--restart '//path//': '//err)
    if (chk%nx /= sim%lp%nx .or. chk%ny /= sim%lp%ny .or. &
        abs(chk%dx - sim%lp%dx) > 1.0e-12_wp*sim%lp%dx .or. &
        abs(chk%dt - sim%lp%dt) > 1.0e-12_wp*sim%lp%dt .or. &
        chk%np /= merge(sim%parts%n, 0, sim%particles_on)) then
      write (msg, '(a,i0,a,i0,a,es12.5,a,es12.5,a,i0,a,i0,a,i0,a,es12.5,a,es12.5,a,i0,a)') &
        ': the checkpoint holds a lattice of ', chk%nx, ' x ', chk%ny, ' cells, dx = ', chk%dx, &
        ' cm, dt = ', chk%dt, ' s with ', chk%np, ' particles; the scene '// &
        'gives ', sim%lp%nx, ' x ', sim%lp%ny, ', dx = ', sim%lp%dx, ', dt = ', sim%lp%dt, &
        ' with ', merge(sim%parts%n, 0, sim%particles_on), '. Resume with the scene file and '// &
        '--set options of the run that wrote it'
      call fatal_all(trim(sim%cfg%file)//': --restart '//path//trim(msg))
    end if
    if (chk%step > sim%lp%steps) then
      write (msg, '(a,i0,a,i0,a)') ': the checkpoint is at step ', chk%step, &
        ', beyond the last step ', sim%lp%steps, ' of the scene; raise run.t_end to continue'
      call fatal_all(trim(sim%cfg%file)//': --restart '//path//trim(msg))
    end if
    sim%step = chk%step
    sim%samples = chk%samples
    sim%win%shift = chk%shift
    do k = 1, size(chk%particles, 2)
      associate (p => sim%parts%p(k), v => chk%particles(:, k))
        p%x = v(1); p%y = v(2); p%u = v(3); p%v = v(4); p%omega = v(5)
        p%fx = v(6); p%fy = v(7); p%torque = v(8); p%cx = v(9); p%cy = v(10)
      end associate
    end do
    if (sim%particles_on) call particles_find_links(sim%parts, sim%dom)
    if (sim%pair_on) then
      sim%pair%n = size(chk%t_start)
      sim%pair%in_episode = chk%in_episode
      sim%pair%t_start = chk%t_start
      sim%pair%t_end = chk%t_end
      sim%pair%gap_min = chk%gap_min
    end if
    sim%restarted = .true.
    sim%restart_from = path
    sim%checkpoints = [path_t(path)]
  end subroutine simulation_restore

  !> The derived lattice parameters, sizes and models of the run, printed by rank 0 before it
  !! starts (and by --check instead of running).
  subroutine simulation_summary(sim)
    type(simulation_t), intent(in) :: sim
    character(len=512) :: line
    character(len=256) :: particles, window
    real(wp) :: s(0:8), mem(3), d1
    integer :: k
    associate (lp => sim%lp, cfg => sim%cfg, dom => sim%dom)
      call log_line('dktlbm '//dkt_version_string//' ('//dkt_git_revision//')')
      write (line, '(a,a,a,i0,a)') 'scene ', trim(cfg%file), ' on ', dom%nranks, ' ranks'
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
      if (sim%particles_move .and. .not. sim%coll%bgk .and. sim%coll%s_q < 0.25_wp) then
        ! measured: the Uhlmann DKT pair at tau = 0.512-0.53 (E3 s_q = 0.05-0.23) blew up at
        ! 20, 30 and 40 spacings per diameter; with s_q = 1.2 it ran through
        write (line, '(a,f6.3,a,f6.4,a)') 'the heat-flux rate s_q = ', sim%coll%s_q, &
          ' (tau = ', lp%tau, ') leaves the q moments almost undamped; with moving '// &
          'particles such runs were measured unstable. Set lbm.s_q = 1.2 (walls then sit '// &
          'slightly off half-way), or raise lbm.tau'
        call warn(trim(line))
      end if
      if (lp%mach > cfg%run%mach_limit) then
        write (line, '(a,es12.4e3,a,es12.4e3,a)') 'the expected Mach number ', lp%mach, &
          ' exceeds run.mach_limit = ', cfg%run%mach_limit, '; the guard will stop the run. '
        call warn(trim(line)//' The velocity scale comes from '// &
                  velocity_scale_source(cfg)//': lower it, or '//dx_knob(cfg)// &
                  ' or lower lbm.tau (both shrink dt)')
      end if
      write (line, '(a,i0,a,i0,a,i0,a,i0,a,i0,a)') 'cells ', lp%nx, ' x ', lp%ny, ' = ', &
        int(lp%nx, i8)*lp%ny, ', steps ', lp%steps, ', rows per rank ', dom%nyl, ' (rank 0)'
      call log_line(trim(line))
      mem = rank_memory(cfg, lp, dom%nxp, dom%nyl)/MIB
      if (sim%particles_on) then
        write (particles, '(a,i0,a,i0,a)') 'particles: ', sim%parts%n, ' (', sim%parts%nlinks, &
          ' boundary links on rank 0)'
      else
        particles = 'particles: none'
      end if
      window = 'window: none'
      if (sim%window_on) then
        d1 = maxval(cfg%particles%diameter(1:cfg%particles%count))
        write (window, '(a,f8.3,a,f6.1,a,f6.1,a,f8.3,a)') 'window: ', lp%ny*lp%dx, ' cm (', &
          cfg%window%below, ' + ', cfg%window%above, ' D_1) from y = ', sim%win%y_origin, ' cm'
      end if
      line = 'memory per rank: lattices '//fixed2(mem(1))//' MiB, particle arrays '// &
             fixed2(mem(2))//' MiB, output buffers '//fixed2(mem(3))//' MiB while writing; '// &
             trim(particles)//'; '//trim(window)
      call log_line(trim(line))
      line = 'models: '//merge('BGK (E4)        ', 'MRT (E1-E3)     ', sim%coll%bgk)
      line = trim(line)//', sides '//trim(cfg%domain%sides)//', lower end '// &
             trim(cfg%domain%lower)//', upper end '//trim(cfg%domain%upper)
      if (sim%coll%forced) line = trim(line)//', body force'
      if (any([cfg%domain%lower, cfg%domain%upper] == 'velocity')) &
        line = trim(line)//', inlet '//trim(cfg%inlet%profile)
      if (cfg%initial%flow /= 'rest') line = trim(line)//', initial '//trim(cfg%initial%flow)
      if (sim%particles_on) then
        line = trim(line)//'; particles on (E6 '//trim(cfg%coupling%bounce_back)// &
               ', E7 '//trim(cfg%coupling%momentum)//', E8-E11)'
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
        write (line, '(a,i0,a)') 'fields every ', k, ' steps and at the end'
      else
        line = 'fields at the end'
      end if
      call log_line(trim(line)//' into '//config_output_dir(cfg)//'/'//cfg%name//'.h5')
    end associate
  end subroutine simulation_summary

  !> The time loop.
  subroutine simulation_run(sim)
    type(simulation_t), intent(inout) :: sim
    real(wp), pointer, contiguous :: tmp(:, :, :)
    integer :: n, nyl, nx, nxp, last_progress, first, flags
    integer, asynchronous :: flags_out, flags_in !! buffers of the flag reduction in flight
    type(MPI_Request) :: request
    logical :: pending
    real(wp) :: t, mach, t_start, t_last, y0, t_checkpoint
    logical :: last
    character(len=256) :: line
    character(len=:), allocatable :: reason, failure
    logical :: ok

    nx = sim%dom%nx
    nyl = sim%dom%nyl
    nxp = sim%dom%nxp
    associate (lp => sim%lp, cfg => sim%cfg)
      if (.not. sim%restarted) then
        if (lp%field_every > 0) call output_fields(sim, 0)
        if (sim%particles_on) call output_particles(sim, 0)
      end if
      call signals_install()
      first = sim%step + 1
      t_start = MPI_Wtime()
      t_last = t_start
      t_checkpoint = t_start
      last_progress = sim%step
      pending = .false.
      failure = ''
      do n = first, lp%steps
        if (sim%particles_on) then
          call particle_step(sim, n)
        else
          ! E1-E5: exchange the crossing populations while the rows that do not need them are
          ! swept, then the two rows next to the slab faces
          call halo_start(sim%dom, sim%f)
          call fill_local_ghosts(sim%bc, sim%dom, sim%f)
          call stream_collide(sim%coll, sim%f, sim%f_next, nxp, nx, nyl, 2, nyl - 1)
          call halo_finish(sim%dom, sim%f)
          call fill_halo_ghosts(sim%bc, sim%dom, sim%f)
          call stream_collide(sim%coll, sim%f, sim%f_next, nxp, nx, nyl, 1, 1)
          call stream_collide(sim%coll, sim%f, sim%f_next, nxp, nx, nyl, nyl, nyl)
          call apply_open_ends(sim%bc, sim%dom, sim%f_next, n)
        end if
        tmp => sim%f
        sim%f => sim%f_next
        sim%f_next => tmp
        sim%step = n
        t = n*lp%dt
        y0 = 0.0_wp
        if (sim%window_on) y0 = window_offset(sim%win, lp%dx)
        if (sim%pair_on) call pair_sample(sim, n)
        last = n == lp%steps .or. len(sim%stopped_early) > 0

        ! a failed guard ends the loop on every rank at once; the output is written below
        if (mod(n, cfg%run%guard_every) == 0 .or. last) then
          call guard_check(sim%dom, sim%f, lp%force_lb, cfg%run%mach_limit, n, t, lp%dx, y0, &
                           mach, failure)
          if (len(failure) > 0) exit
        end if
        if (lp%field_every > 0) then
          if (mod(n, lp%field_every) == 0 .and. .not. last) call output_fields(sim, n)
        end if
        if (sim%particles_on .and. lp%series_every > 0) then
          if (mod(n, lp%series_every) == 0 .and. .not. last) call output_particles(sim, n)
        end if
        if (cfg%run%progress_every > 0) then
          if (mod(n, cfg%run%progress_every) == 0 .and. .not. last) then
            ! the progress line reports the current Mach number, which the guard measures
            if (mod(n, cfg%run%guard_every) /= 0) then
              call guard_check(sim%dom, sim%f, lp%force_lb, cfg%run%mach_limit, n, t, lp%dx, &
                               y0, mach, failure)
              if (len(failure) > 0) exit
            end if
            call progress(n, last_progress, t_last, t_start, mach)
          end if
        end if
        ! checkpoints: every checkpoint_every steps, every checkpoint_wall seconds (rank 0's
        ! clock), and before stopping on a signal or at the wall limit. The ranks agree on the
        ! signal and clock flags with a reduction started one step earlier, so that no step
        ! waits for it; every rank acts on the same flags at the same step.
        flags = 0
        if (pending) then
          call MPI_Wait(request, MPI_STATUS_IGNORE)
          flags = flags_in
          pending = .false.
        end if
        if (.not. last .and. (btest(flags, 0) .or. btest(flags, 2))) then
          call write_checkpoint(sim)
          sim%interrupted = .true.
          if (btest(flags, 0)) then
            reason = 'on signal '//trim(merge('SIGTERM', 'SIGUSR1', &
                                              signal_caught() == SIGTERM .or. &
                                              signal_caught() == 0))
            sim%stop_reason = 'signal'
          else
            reason = 'at run.wall_limit'
            sim%stop_reason = 'wall_limit'
          end if
          exit
        end if
        if (last) exit ! (a checkpoint at the last step follows the final output)
        if (btest(flags, 1) .or. cfg%run%checkpoint_every > 0) then
          if (btest(flags, 1) .or. mod(n, max(1, cfg%run%checkpoint_every)) == 0) then
            call write_checkpoint(sim)
            t_checkpoint = MPI_Wtime()
          end if
        end if
        flags_out = 0
        if (signal_caught() /= 0) flags_out = ibset(flags_out, 0)
        if (sim%dom%rank == 0) then
          if (cfg%run%checkpoint_wall > 0.0_wp .and. &
              MPI_Wtime() - t_checkpoint >= cfg%run%checkpoint_wall) &
            flags_out = ibset(flags_out, 1)
          if (cfg%run%wall_limit > 0.0_wp .and. MPI_Wtime() - t_start >= cfg%run%wall_limit) &
            flags_out = ibset(flags_out, 2)
        end if
        call MPI_Iallreduce(flags_out, flags_in, 1, MPI_INTEGER, MPI_BOR, sim%dom%comm, request)
        pending = .true.
      end do
      ! a guard stop leaves the flag reduction of the step before in flight
      if (pending) call MPI_Wait(request, MPI_STATUS_IGNORE)
      n = sim%step
      if (len(failure) > 0) then
        ! every rank saw the same failure: write the last step's state (what went wrong is
        ! in it), close the output, then stop with the message
        sim%stop_reason = 'guard: '//failure
        call log_line('stopped by a guard after step '//itoa(n)//' of '//itoa(lp%steps)// &
                      '; the output holds the run up to this step')
        call output_close(sim)
        call fatal_all(failure, EXIT_RUNTIME)
      end if
      t = MPI_Wtime() - t_start
      write (line, '(a,f9.2,a,i0,a,i0,a,f9.3,a,i0,a)') 'performance: ', &
        real(lp%nx, wp)*real(lp%ny, wp)*real(n - first + 1, wp)/max(t, 1.0e-9_wp)/1.0e6_wp, &
        ' MLUPS (', int(lp%nx, i8)*lp%ny, ' cells x ', n - first + 1, ' steps in ', t, &
        ' s on ', sim%dom%nranks, ' ranks)'
      call log_line(trim(line))
      if (sim%interrupted) then
        call log_line('stopped '//reason//' after step '//itoa(n)//' of '//itoa(lp%steps)// &
                      '; checkpoint '//sim%checkpoints(size(sim%checkpoints))%s// &
                      ' written. Resume with:')
        call log_line('  '//resume_command(sim%checkpoints(size(sim%checkpoints))%s, &
                                           sim%dom%nranks))
        ! the output up to this step; a resumed run cuts back what the checkpoint has not
        call output_close(sim)
        return
      end if
      sim%stop_reason = 'finished'
      if (len(sim%stopped_early) > 0) then
        sim%stop_reason = 'window_escape'
        call warn(sim%stopped_early)
      end if
      if (sim%fields_step /= n) call output_fields(sim, n)
      if (sim%particles_on .and. sim%series_step /= n) call output_particles(sim, n)
      if (sim%pair_on) call output_pair_report(sim)
      ! a checkpoint at the last step lets the run be extended (a larger run.t_end); the final
      ! sample counts only when it is on the series schedule, as in a longer run
      if (cfg%run%checkpoint_every > 0) then
        if (mod(n, cfg%run%checkpoint_every) == 0) &
          call write_checkpoint(sim, merge(1, 0, sim%particles_on .and. &
                                           mod(n, lp%series_every) /= 0))
      end if
      call output_close(sim)
      ok = .true.
      if (sim%dom%rank == 0) ok = write_marker(config_output_dir(cfg)//'/'//cfg%name// &
                                               '.finished', itoa(n))
      call MPI_Bcast(ok, 1, MPI_LOGICAL, 0, sim%dom%comm)
      if (.not. ok) call fatal_all('cannot write the marker file '''// &
                                   config_output_dir(cfg)//'/'//cfg%name//'.finished'''// &
                                   ': the run finished and its output is complete, but '// &
                                   'batch scripts that wait for this file will not see it; '// &
                                   'check that output.dir is writable', EXIT_RUNTIME)
    end associate
  contains
    subroutine progress(n, last, t_last, t_start, mach)
      integer, intent(in) :: n
      integer, intent(inout) :: last
      real(wp), intent(inout) :: t_last
      real(wp), intent(in) :: t_start, mach
      real(wp) :: now, mlups, eta
      integer :: h, m, s
      now = MPI_Wtime()
      mlups = real(sim%lp%nx, wp)*real(sim%lp%ny, wp)*real(n - last, wp)/ &
              max(now - t_last, 1.0e-9_wp)/1.0e6_wp
      ! the time per step of this process (a resumed run started at step first - 1)
      eta = (now - t_start)/real(n - first + 1, wp)*real(sim%lp%steps - n, wp)
      h = int(eta)/3600
      m = mod(int(eta), 3600)/60
      s = mod(int(eta), 60)
      write (line, '(a,i0,a,i0,a,es11.4,a,f9.4,a,f7.4,a,f9.2,a,i0,a,i2.2,a,i2.2)') 'step ', n, &
        '/', sim%lp%steps, '  t = ', n*sim%lp%dt, ' s  t* = ', n*sim%lp%dt/sim%cfg%run%t_ref, &
        '  Ma = ', mach, '  MLUPS ', mlups, '  ETA ', h, ':', m, ':', s
      call log_line(trim(line))
      last = n
      t_last = now
    end subroutine progress
  end subroutine simulation_run

  !> Write the checkpoint of the current step, name it in <dir>/<name>.checkpoint and delete
  !! the checkpoints beyond run.checkpoint_keep. A failed write stops the run; the checkpoint
  !! written before stays as it was.
  subroutine write_checkpoint(sim, unscheduled)
    type(simulation_t), intent(inout) :: sim
    integer, intent(in), optional :: unscheduled !! samples written off the series schedule
    type(checkpoint_t) :: chk
    character(len=:), allocatable :: dir, path, err, before
    integer :: k
    logical :: ok
    dir = config_output_dir(sim%cfg)
    path = checkpoint_name(dir, sim%cfg%name, sim%step)
    chk%step = sim%step
    chk%shift = sim%win%shift
    chk%samples = sim%samples
    if (present(unscheduled)) chk%samples = sim%samples - unscheduled
    chk%nx = sim%lp%nx
    chk%ny = sim%lp%ny
    chk%dx = sim%lp%dx
    chk%dt = sim%lp%dt
    allocate (chk%particles(NSTATE, merge(sim%parts%n, 0, sim%particles_on)))
    do k = 1, size(chk%particles, 2)
      associate (p => sim%parts%p(k))
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
    call checkpoint_write(path, sim%dom%comm, sim%f, sim%lp%nx, sim%dom%nyl, sim%dom%y0, chk, &
                          sim%cfg%given, err)
    if (len(err) > 0) then
      before = 'none'
      if (allocated(sim%checkpoints)) then
        if (size(sim%checkpoints) > 0) before = sim%checkpoints(size(sim%checkpoints))%s
      end if
      call output_fail(sim, err//'. The last checkpoint written is '//before)
    end if
    if (.not. allocated(sim%checkpoints)) allocate (sim%checkpoints(0))
    sim%checkpoints = [sim%checkpoints, path_t(path)]
    ok = .true.
    if (sim%dom%rank == 0) ok = write_marker(dir//'/'//sim%cfg%name//'.checkpoint', path)
    call MPI_Bcast(ok, 1, MPI_LOGICAL, 0, sim%dom%comm)
    ! batch scripts resume from the checkpoint the marker names: a stale one would lose steps
    if (.not. ok) call output_fail(sim, 'cannot write the marker file '''//dir//'/'// &
                                   sim%cfg%name//'.checkpoint'' naming the checkpoint '// &
                                   path//'; check that output.dir is writable')
    do while (size(sim%checkpoints) > sim%cfg%run%checkpoint_keep)
      if (sim%dom%rank == 0) call remove_file(sim%checkpoints(1)%s)
      sim%checkpoints = sim%checkpoints(2:)
    end do
    call log_line('checkpoint '//path)
  end subroutine write_checkpoint

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

  !> One step with particles: the halo is completed before the sweep because a boundary link
  !! next to a slab face reads the neighbour's populations (E6), then the bounced populations
  !! are set, the lattice swept, forces summed (E7), the particles moved (E8–E11) and the
  !! window moved after them (docs/model.md §5), before the boundary links are found for the
  !! next step.
  subroutine particle_step(sim, n)
    type(simulation_t), intent(inout) :: sim
    integer, intent(in) :: n
    call halo_start(sim%dom, sim%f)
    call fill_local_ghosts(sim%bc, sim%dom, sim%f)
    call halo_finish(sim%dom, sim%f)
    call fill_halo_ghosts(sim%bc, sim%dom, sim%f)
    call particles_bounce(sim%parts, sim%dom, sim%f)
    call stream_collide(sim%coll, sim%f, sim%f_next, sim%dom%nxp, sim%dom%nx, sim%dom%nyl, 1, &
                        sim%dom%nyl)
    call apply_open_ends(sim%bc, sim%dom, sim%f_next, n)
    call particles_interior(sim%parts, sim%dom, sim%f_next)
    call particles_reduce_forces(sim%parts, sim%dom)
    ! the owners move their particles (fixed ones stay) and send every rank the new state
    call particles_move(sim%parts, sim%dom, sim%f_next, &
                        sim%cfg%domain%lower == 'wall' .and. sim%cfg%domain%upper == 'wall')
    if (sim%window_on) call follow_particles(sim, n)
    if (sim%particles_move) call check_particle_places(sim, n)
    if (sim%particles_move) call particles_find_links(sim%parts, sim%dom)
  end subroutine particle_step

  !> Stop every rank when a particle left the lattice (its centre beyond a side or an end), a
  !! prescribed particle reached a wall, or a prescribed particle entered another body: a
  !! fixed or prescribed one at contact, a free one deeper than the larger radius (a free
  !! particle normally makes way; one pinned against a wall cannot). The input check refuses
  !! what a constant prescribed velocity makes predictable; this catches what it cannot
  !! (a moving window, free particles). Every rank holds the same particle states, so every
  !! rank stops at the same step.
  subroutine check_particle_places(sim, n)
    type(simulation_t), intent(in) :: sim
    integer, intent(in) :: n
    real(wp) :: nx, ny, y0, dist, reach
    integer :: k, m
    character(len=:), allocatable :: what
    character(len=160) :: where
    logical :: walls_x, wall_lo, wall_hi
    nx = real(sim%lp%nx, wp)
    ny = real(sim%lp%ny, wp)
    walls_x = sim%cfg%domain%sides == 'wall'
    wall_lo = sim%cfg%domain%lower == 'wall' .and. .not. sim%window_on
    wall_hi = sim%cfg%domain%upper == 'wall' .and. .not. sim%window_on
    do k = 1, sim%parts%n
      what = ''
      associate (p => sim%parts%p(k))
        if (p%x < 0.0_wp .or. p%x > nx) then
          what = 'its centre left the channel through a side'
        else if (p%y < 0.0_wp) then
          what = 'its centre passed the lower end'//trim(merge(' of the window', '              ', &
                                                               sim%window_on))
        else if (p%y > ny) then
          what = 'its centre passed the upper end'//trim(merge(' of the window', '              ', &
                                                               sim%window_on))
        else if (p%motion == MOTION_PRESCRIBED) then
          if (walls_x .and. (p%x < p%r .or. p%x > nx - p%r)) what = 'it reached a side wall'
          if (wall_lo .and. p%y < p%r) what = 'it reached the lower end'
          if (wall_hi .and. p%y > ny - p%r) what = 'it reached the upper end'
          do m = 1, sim%parts%n
            if (m == k) cycle
            associate (q => sim%parts%p(m))
              dist = hypot(p%x - q%x, p%y - q%y)
              reach = p%r + q%r
              if (q%motion == MOTION_FREE) reach = max(p%r, q%r)
              if (dist < reach) what = 'it entered particle '//itoa(m)
            end associate
          end do
        end if
        if (len(what) == 0) cycle
        y0 = 0.0_wp
        if (sim%window_on) y0 = window_offset(sim%win, sim%lp%dx)
        write (where, '(a,es12.5,a,es12.5,a,i0,a,es12.5,a)') ' at (x, y) = (', &
          p%x*sim%lp%dx, ',', p%y*sim%lp%dx + y0, ') cm, step ', n, ' (t = ', n*sim%lp%dt, ' s)'
      end associate
      call fatal_all(trim(sim%cfg%file)//': particle '//itoa(k)//' (motion = '// &
                     quoted_motion(sim%cfg%particles%motion(k))//'): '//what//trim(where)// &
                     '; the run stops. Change its velocity or start (&particles u, v, x, y of '// &
                     'particle '//itoa(k)//'), or end the run earlier', EXIT_RUNTIME)
    end do
  contains
    function quoted_motion(m) result(q)
      character(len=*), intent(in) :: m
      character(len=:), allocatable :: q
      q = ''''//trim(m)//''''
    end function quoted_motion
  end subroutine check_particle_places

  !> docs/model.md §5: move the window (the new populations in f_next) with the lowest particle; a
  !! particle near the upper end (the pair has separated by more than the window holds) ends
  !! the run after this step.
  subroutine follow_particles(sim, n)
    type(simulation_t), intent(inout) :: sim
    integer, intent(in) :: n
    integer :: k
    character(len=320) :: msg
    call window_follow(sim%win, sim%dom, sim%parts, sim%f_next)
    k = window_escaped(sim%win, sim%parts, sim%lp%ny)
    if (k > 0) then
      write (msg, '(a,i0,a,i0,a,es11.4,a,f7.2,a)') 'particle ', k, &
        ' came within window.margin of the window''s upper end at step ', n, ' (t = ', &
        n*sim%lp%dt, ' s): the particles separated by more than the window holds ('// &
        'window.above = ', sim%cfg%window%above, ' D_1); the run ends here. Raise '// &
        'window.above to follow them further'
      sim%stopped_early = trim(msg)
    end if
  end subroutine follow_particles

  !> The gap of particles 1 and 2 after step n, for the kissing episodes (docs/model.md §6); every
  !! step, so that no episode falls between two samples of the series.
  subroutine pair_sample(sim, n)
    type(simulation_t), intent(inout) :: sim
    integer, intent(in) :: n
    real(wp) :: gx, gy, gr
    associate (a => sim%parts%p(1), b => sim%parts%p(2))
      call pair_gaps(a%x, a%y, a%r, b%x, b%y, b%r, gx, gy, gr)
    end associate
    call pair_diag_update(sim%pair, n*sim%lp%dt, gr)
  end subroutine pair_sample

  subroutine simulation_finish(sim)
    type(simulation_t), intent(inout) :: sim
    if (sim%output_open) call io_close(sim%io)
    sim%output_open = .false.
    if (sim%csv_open) close (sim%csv_unit)
    sim%csv_open = .false.
    call log_close()
    if (associated(sim%f)) deallocate (sim%f, sim%f_next)
    call domain_free(sim%dom)
  end subroutine simulation_finish

end module dkt_simulation

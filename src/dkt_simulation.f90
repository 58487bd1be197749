!> A flow simulation on MPI slabs: set-up from the configuration and one time step
!> (simulation_step, docs/model.md §1–2): stream-collide with the boundaries, the particles and
!> the window. The time loop around it, with the guards and the services, is dkt_run's.
module dkt_simulation
  use ieee_arithmetic, only: ieee_is_finite, ieee_value, ieee_quiet_nan
  use mpi_f08, only: MPI_Comm
  use dkt_kinds, only: wp, i8
  use dkt_errors, only: fatal_all, internal_error
  use dkt_config, only: config_t, lattice_params_t
  use dkt_mrt, only: collision_init, sweep_init, sweep_rows
  use dkt_store, only: lattice_t, lattice_allocate, lattice_free, &
                       lattice_swap, lattice_allocated, lattice_precision
  use dkt_domain, only: domain_t, domain_init, domain_free, halo_start, halo_finish, &
                        domain_resize, domain_move_rows, domain_fill_new_rows, MIN_SLAB_ROWS, &
                        domain_split
  use dkt_boundary, only: boundary_init, fill_local_ghosts, fill_halo_ghosts, apply_open_ends
  use dkt_lubrication, only: lubrication_t
  use dkt_initial, only: initial_state
  use dkt_particles, only: particles_init, particles_stable_substeps, particles_resize_rows, &
                           particles_reach_rows, particles_exchange, particles_agree, &
                           particles_min, particles_first_above_own
  use dkt_links, only: links_init, links_find, links_bounce, links_interior, &
                       links_interior_after_move, links_inner_save, links_inner_write, &
                       links_refill, links_reduce_forces, links_fluid_interior
  use dkt_particle_motion, only: particles_move
  use dkt_balance, only: balance_plan, balance_line
  use dkt_choices, only: END_WALL, END_PERIODIC, END_VELOCITY, END_OUTFLOW, MOTION_FREE, &
                         MOTION_FIXED, MOTION_PRESCRIBED, &
                         BB_HALFWAY, BB_YU, BB_BFL, PROFILE_PARABOLIC, COLLISION_BGK, &
                         STREAMING_IN_PLACE, MOMENTUM_GALILEAN, INTERIOR_FLUID
  use dkt_diagnostics, only: guard_set_advice, guard_particle_speed, pair_diag_init, &
                             pair_diag_update, pair_gaps
  use dkt_window, only: window_init, window_offset, window_follow, window_escaped, &
                        window_escape_line
  use dkt_log, only: log_line, log_close
  use dkt_memory, only: check_memory
  use dkt_text, only: itoa, fmt_real
  use dkt_run_state, only: simulation_t
  use dkt_timers, only: timer_start, timer_stop, PART_FLOW, PART_LINKS, PART_PARTICLES, &
                        PART_WINDOW, PART_GUARDS
  implicit none
  private
  public :: simulation_t, simulation_setup, simulation_step, simulation_finish, simulation_grow, &
            simulation_settle

  !> the most particle sub-steps per fluid step a run takes (docs/running.md): more means a
  !! contact law so stiff (collision.stiffness far below its default) that the run never ends
  integer, parameter :: MAX_SUBSTEPS = 10000

contains

  !> Decompose, check that the memory the run needs is there, allocate the two lattices and
  !! set the initial state. Every rank calls it; a decomposition that cannot work stops all
  !! ranks with the largest rank count that does, a run that needs more memory than a node
  !! gives stops them before anything large is allocated. `lattices` = .false. (--check) sets
  !! up everything the start-up report needs but allocates no lattice. `ny` is the rows the run
  !! starts on: lp%ny, or more for a run resumed on a window that grew (the domain keeps the
  !! current count; lp stays as load computed it).
  subroutine simulation_setup(sim, cfg, lp, comm, ny, lattices)
    type(simulation_t), intent(inout) :: sim
    type(config_t), intent(in) :: cfg
    type(lattice_params_t), intent(in) :: lp
    type(MPI_Comm), intent(in) :: comm
    integer, intent(in) :: ny
    logical, intent(in), optional :: lattices
    logical :: with_lattices
    character(len=:), allocatable :: err
    logical :: periodic_x, periodic_y
    integer :: min_rows
    logical :: single, shifted, arith4, half
    type(domain_t) :: largest

    sim%cfg = cfg
    sim%lp = lp
    periodic_x = cfg%domain%sides_kind == END_PERIODIC
    periodic_y = cfg%domain%lower_kind == END_PERIODIC
    sim%particles_on = lp%particles_on
    min_rows = MIN_SLAB_ROWS
    if (sim%particles_on) then
      ! a slab holds at least the largest particle plus its interpolation stencil, and is
      ! thicker than a disk with the reach within which a slab holds it as a ghost, so that a
      ! ghost's owner is always a neighbouring slab (dkt_particles)
      min_rows = max(min_rows, ceiling(lp%largest_diameter/lp%dx) + 4, &
                     particles_reach_rows(0.5_wp*lp%largest_diameter/lp%dx, cfg%collision%range))
    end if
    sim%min_rows = min_rows
    call domain_init(sim%dom, comm, lp%nx, ny, periodic_x, periodic_y, min_rows, err)
    if (len(err) > 0) call fatal_all(trim(cfg%file)//': '//err)
    if (lp%ny_max > ny) then
      ! a window that may grow (docs/model.md §5) is refused now, not at a growth mid-run, when
      ! the node cannot hold its largest lattice
      largest = sim%dom
      call domain_resize(largest, lp%ny_max)
      call check_memory(sim%cfg, sim%lp, largest)
    else
      call check_memory(sim%cfg, sim%lp, sim%dom)
    end if
    with_lattices = .true.
    if (present(lattices)) with_lattices = lattices
    call boundary_init(sim%bc, periodic_x, cfg%domain%lower_kind, cfg%domain%upper_kind, &
                       lp%u_in_lb, cfg%inlet%profile_kind == PROFILE_PARABOLIC, &
                       cfg%inlet%ramp_time/lp%dt)
    call collision_init(sim%coll, lp%s, cfg%lbm%collision_kind == COLLISION_BGK, lp%force_lb)
    if (with_lattices) then
      call lattice_precision(cfg%lbm%precision_kind, single, shifted, arith4, half)
      sim%in_place = cfg%lbm%streaming_kind == STREAMING_IN_PLACE
      call lattice_allocate(sim%f, sim%dom%nxp, sim%dom%nyl, single, shifted, arith4, half)
      if (sim%in_place) then
        sim%f_next = sim%f
      else
        call lattice_allocate(sim%f_next, sim%dom%nxp, sim%dom%nyl, single, shifted, arith4, half)
      end if
      call sweep_init(sim%ws, sim%dom%nxp)
      call initial_state(sim%cfg, sim%lp, sim%dom, sim%f)
    end if
    sim%window_on = cfg%window%enabled
    if (sim%window_on) then
      associate (d1 => lp%largest_diameter/lp%dx)
        call window_init(sim%win, lp%window_bottom, cfg%window%below*d1, cfg%window%margin*d1)
      end associate
    end if
    if (sim%particles_on) call setup_particles(sim)
    ! the guards' advice names the knob that sets dx in this scene, and s_q where it is the
    ! measured cause of a run-away flow
    call guard_set_advice(lp%dx_knob, sim%coll%s_q, sim%particles_move .and. .not. sim%coll%bgk)
    ! a pair scene, two particles, or diagnostics.pair: a suspension follows no pair
    sim%pair_on = lp%pair_on
    if (sim%pair_on) call pair_diag_init(sim%pair, lp%kiss_enter, lp%kiss_release)
    sim%stopped_early = ''
    sim%fast = ''
  end subroutine simulation_setup

  !> The particles of the scene in lattice units (docs/model.md §3–4), their first boundary links
  !! and the fluid inside them set to their velocity.
  subroutine setup_particles(sim)
    type(simulation_t), intent(inout) :: sim
    integer :: n, k, nsub
    integer, allocatable :: motion(:)
    integer :: scheme
    character(len=256) :: line
    character(len=:), allocatable :: needs
    type(lubrication_t) :: lub
    n = sim%cfg%particles%count
    allocate (motion(n))
    do k = 1, n
      motion(k) = sim%cfg%particles%motion_kind(k)
      select case (motion(k))
      case (MOTION_FREE, MOTION_FIXED, MOTION_PRESCRIBED)
      case default
        call internal_error('setup_particles: particles.motion code '//itoa(motion(k)))
      end select
    end do
    scheme = sim%cfg%coupling%bounce_back_kind
    select case (scheme)
    case (BB_HALFWAY, BB_YU, BB_BFL)
    case default
      call internal_error('setup_particles: coupling.bounce_back code '//itoa(scheme))
    end select
    ! lattice units throughout (lattice_from); y counts from the window's lower end at t = 0
    ! E13 in lattice units: mu = rho_f nu_lb with rho_f = 1, gaps in spacings
    lub%on = sim%cfg%collision%lubrication
    lub%mu = sim%lp%nu_lb
    lub%cutoff = sim%cfg%collision%lubrication_range
    lub%hmin = sim%cfg%collision%lubrication_min
    associate (p => sim%lp%particles, c => sim%cfg%collision)
      call particles_init(sim%parts, sim%dom, p%x, p%y, p%r, p%u, p%v, p%omega, p%density, &
                          motion, p%gravity, p%stiffness, p%stiffness_overlap, c%range, &
                          c%substeps, sim%cfg%coupling%average_force, lub)
    end associate
    call links_init(sim%links, sim%dom, scheme, &
                    sim%cfg%coupling%momentum_kind == MOMENTUM_GALILEAN, &
                    sim%cfg%coupling%interior_kind == INTERIOR_FLUID)
    sim%particles_move = any(motion /= MOTION_FIXED)
    ! docs/model.md §4: a stiff contact law is sub-stepped, not softened, and the log says so;
    ! more than MAX_SUBSTEPS means a stiffness far off (a run that would never end) and is refused
    nsub = particles_stable_substeps(sim%parts)
    if (nsub > MAX_SUBSTEPS) then
      needs = itoa(nsub)
      if (nsub == huge(nsub)) needs = 'more than '//needs
      call fatal_all(trim(sim%cfg%file)//': &collision stiffness = '// &
                     fmt_real(sim%cfg%collision%stiffness)//', stiffness_overlap = '// &
                     fmt_real(sim%cfg%collision%stiffness_overlap)//': the explicit particle '// &
                     'update needs '//needs//' sub-steps per fluid step to stay stable; '// &
                     'allowed: at most '//itoa(MAX_SUBSTEPS)//' sub-steps; make stiffness '// &
                     'and stiffness_overlap larger (a softer contact law)')
    end if
    sim%substep_note = ''
    if (nsub > sim%parts%substeps) then
      write (line, '(a,i0,a,i0,a)') 'collision stiffness: the explicit particle update needs ', &
        nsub, ' sub-steps per fluid step to stay stable; '// &
        'using them instead of collision.substeps = ', sim%parts%substeps, &
        ' (the contact law is unchanged)'
      sim%parts%substeps = nsub
      ! the start-up summary prints it (report_summary), after the banner
      sim%substep_note = trim(line)
    end if
    call links_find(sim%links, sim%parts, sim%dom)
    if (lattice_allocated(sim%f)) call links_interior(sim%links, sim%parts, sim%dom, sim%f)
  end subroutine setup_particles

  !> One time step n of the solver (docs/model.md §1–2): stream-collide with the boundaries,
  !! and with particles E6–E11 and the window; f_next becomes f, and the pair's gap is sampled.
  !! `failure` says why a particle is out of place ('' if none).
  subroutine simulation_step(sim, n, failure)
    type(simulation_t), intent(inout) :: sim
    integer, intent(in) :: n
    character(len=:), allocatable, intent(out) :: failure
    if (sim%particles_on) then
      call particle_step(sim, n, failure)
    else
      failure = ''
      call fluid_step(sim, n)
    end if
    call swap_lattices(sim)
    sim%step = n
    sim%updates = sim%updates + int(sim%lp%nx, i8)*int(sim%dom%ny, i8)
    if (sim%pair_on) then
      call timer_start(PART_PARTICLES)
      call pair_sample(sim, n)
      call timer_stop(PART_PARTICLES)
    end if
  end subroutine simulation_step

  !> One step without particles (E1-E5): exchange the crossing populations while the rows that
  !! do not need them are swept, then the two rows next to the slab faces; open ends last.
  subroutine fluid_step(sim, n)
    type(simulation_t), intent(inout) :: sim
    integer, intent(in) :: n
    call timer_start(PART_FLOW)
    call halo_start(sim%dom, sim%f)
    call fill_local_ghosts(sim%bc, sim%dom, sim%f)
    call sweep_part(sim, 1)
    call halo_finish(sim%dom, sim%f)
    call fill_halo_ghosts(sim%bc, sim%dom, sim%f)
    call sweep_part(sim, 2)
    call apply_open_ends(sim%bc, sim%dom, sim%f_next, n)
    call timer_stop(PART_FLOW)
  end subroutine fluid_step

  !> Stream and collide the rows that do not read the halo rows (part 1, while the halo
  !! travels) or the rest (part 2, once it has arrived and the boundary links of the rows next to
  !! the faces are bounced).
  !!
  !! Two lattices: part 1 is rows 2..nyl-1, part 2 rows 1 and nyl. In place, a row may be
  !! overwritten only after the rows that pull from it have read it, and the bounce-back of the
  !! links of rows 1 and nyl (after part 1) reads rows 0..2 and nyl-1..nyl+1 as they were: part 1
  !! is rows 3..nyl-2, keeping its old end rows, which parts 2 (rows 1..2 and nyl-1..nyl) pull
  !! from. A slab of fewer than 6 rows is swept whole in part 2. Every node sees the same
  !! values in either scheme, so the two give the same bits (tests/test_mrt.f90).
  subroutine sweep_part(sim, part)
    type(simulation_t), intent(inout) :: sim
    integer, intent(in) :: part
    associate (nx => sim%dom%nx, nyl => sim%dom%nyl, c => sim%coll, ws => sim%ws, &
               f => sim%f, g => sim%f_next)
      if (.not. sim%in_place) then
        if (part == 1) then
          call sweep_rows(c, ws, f, g, nx, nyl, 2, nyl - 1)
        else
          call sweep_rows(c, ws, f, g, nx, nyl, 1, 1)
          call sweep_rows(c, ws, f, g, nx, nyl, nyl, nyl)
        end if
      else if (nyl < 6) then
        if (part == 2) call sweep_rows(c, ws, f, f, nx, nyl, 1, nyl)
      else if (part == 1) then
        call sweep_rows(c, ws, f, f, nx, nyl, 3, nyl - 2, keep=.true.)
      else
        call sweep_rows(c, ws, f, f, nx, nyl, 1, 2, above_kept=.true.)
        call sweep_rows(c, ws, f, f, nx, nyl, nyl - 1, nyl, below_kept=.true.)
      end if
    end associate
  end subroutine sweep_part

  !> f_next (written by the sweep) becomes the current lattice f.
  subroutine swap_lattices(sim)
    type(simulation_t), intent(inout) :: sim
    call lattice_swap(sim%f, sim%f_next)
  end subroutine swap_lattices

  !> One step with particles, overlapped like fluid_step: while the crossing populations
  !! travel, the links whose fluid node lies in rows 2..nyl-1 are bounced (E6) and those rows
  !! swept; their links read and write no halo row, and the solid slots they set are pulled only
  !! by their own fluid nodes. Then the links of rows 1 and nyl (Yu and BFL read a second fluid
  !! node in the halo row, and a solid node there is overwritten by the exchange) and those two
  !! rows. Each node sees the same operations in the same order as with the halo completed
  !! first, and each row's force sum adds its links in the same order, so the bits do not
  !! change. Forces are summed (E7), the particles moved (E8–E11) and the window moved after
  !! them (docs/model.md §5), before the boundary links are found for the next step. With
  !! interior fluid the flow part is fluid_interior_sweep instead, and no node is reset.
  subroutine particle_step(sim, n, failure)
    type(simulation_t), intent(inout) :: sim
    integer, intent(in) :: n
    character(len=:), allocatable, intent(out) :: failure !! '' or why a particle is out of place
    failure = ''
    if (links_fluid_interior(sim%links)) then
      call fluid_interior_sweep(sim)
    else
      associate (nyl => sim%dom%nyl)
        call timer_start(PART_FLOW)
        call halo_start(sim%dom, sim%f)
        call fill_local_ghosts(sim%bc, sim%dom, sim%f)
        call timer_stop(PART_FLOW)
        call timer_start(PART_LINKS)
        call links_bounce(sim%links, sim%parts, sim%dom, sim%f, 2, nyl - 1)
        call timer_stop(PART_LINKS)
        call timer_start(PART_FLOW)
        call sweep_part(sim, 1)
        call halo_finish(sim%dom, sim%f)
        call fill_halo_ghosts(sim%bc, sim%dom, sim%f)
        call timer_stop(PART_FLOW)
        call timer_start(PART_LINKS)
        call links_bounce(sim%links, sim%parts, sim%dom, sim%f, 1, 1)
        call links_bounce(sim%links, sim%parts, sim%dom, sim%f, nyl, nyl)
        call timer_stop(PART_LINKS)
        call timer_start(PART_FLOW)
        call sweep_part(sim, 2)
        call timer_stop(PART_FLOW)
      end associate
    end if
    call timer_start(PART_FLOW)
    call apply_open_ends(sim%bc, sim%dom, sim%f_next, n)
    call timer_stop(PART_FLOW)
    ! the interior nodes: reset after the move, and only when something reads the lattice
    ! (simulation_settle) or moves its rows (a window's shift or growth, a balance), on the slabs
    ! and rows they are on now; fixed disks' at once
    sim%interior_due = .false.
    if (.not. links_fluid_interior(sim%links)) then
      if (sim%particles_move) then
        sim%interior_due = .true.
      else
        call timer_start(PART_LINKS)
        call links_interior(sim%links, sim%parts, sim%dom, sim%f_next)
        call timer_stop(PART_LINKS)
      end if
    end if
    call timer_start(PART_PARTICLES)
    ! each owner adds the rows of its particles' links, those of the neighbouring slabs too
    call links_reduce_forces(sim%links, sim%parts, sim%dom)
    ! the owners move their particles (fixed ones stay) and send the new states to the
    ! neighbouring slabs that hold them; the nodes the disks uncovered are refilled
    call particles_move(sim%parts, sim%dom, ends_at_rest(sim), sim%particles_move)
    if (sim%particles_move) call links_refill(sim%links, sim%parts, sim%dom, sim%f_next)
    call timer_stop(PART_PARTICLES)
    call timer_start(PART_WINDOW)
    if (sim%window_on) call follow_particles(sim)
    call timer_stop(PART_WINDOW)
    call timer_start(PART_GUARDS)
    call survey_step(sim, n, failure)
    call timer_stop(PART_GUARDS)
    if (len(failure) == 0) call balance_step(sim, n)
    call timer_start(PART_LINKS)
    ! (links of a particle outside the lattice do not exist: the loop stops instead)
    if (sim%particles_move .and. len(failure) == 0) call links_find(sim%links, sim%parts, sim%dom)
    call timer_stop(PART_LINKS)
  end subroutine particle_step

  !> Complete the last step's lattice before it is read whole (output, guards, checkpoints):
  !! the interior nodes of the disks get the equilibrium at the disk's velocity that the step
  !! left for later (particle_step). Without this the interior nodes, which nothing in a step
  !! reads, hold whatever their own sweep gave them; with it the lattice is the same, bit for
  !! bit, as when every step resets them. Cheap to call again: it does the work once a step.
  subroutine simulation_settle(sim)
    type(simulation_t), intent(inout) :: sim
    if (.not. sim%interior_due) return
    call timer_start(PART_LINKS)
    call links_interior_after_move(sim%links, sim%parts, sim%dom, sim%f)
    call timer_stop(PART_LINKS)
    sim%interior_due = .false.
  end subroutine simulation_settle

  !> The flow part of a step with interior fluid (coupling.interior = 'fluid', docs/model.md §3),
  !! without overlap: the halo completes first; the interior links save what their nodes
  !! receive (this reads the slots E6 then overwrites); E6/E7 on every boundary link; the
  !! interior values go into the slots of the outer nodes (E6 and E7 have read them); then
  !! every row is swept. Both parts of the sweep follow one another with nothing written in
  !! between, so the in-place sweep sees what the two-lattice one sees.
  subroutine fluid_interior_sweep(sim)
    type(simulation_t), intent(inout) :: sim
    call timer_start(PART_FLOW)
    call halo_start(sim%dom, sim%f)
    call fill_local_ghosts(sim%bc, sim%dom, sim%f)
    call halo_finish(sim%dom, sim%f)
    call fill_halo_ghosts(sim%bc, sim%dom, sim%f)
    call timer_stop(PART_FLOW)
    call timer_start(PART_LINKS)
    call links_inner_save(sim%links, sim%parts, sim%dom, sim%f)
    call links_bounce(sim%links, sim%parts, sim%dom, sim%f, 1, sim%dom%nyl)
    call links_inner_write(sim%links, sim%f)
    call timer_stop(PART_LINKS)
    call timer_start(PART_FLOW)
    call sweep_part(sim, 1)
    call sweep_part(sim, 2)
    call timer_stop(PART_FLOW)
  end subroutine fluid_interior_sweep

  !> The ends a disk collides with by E11 (docs/model.md §4), lower and upper: the ends at
  !! rest, a 'wall' or a 'velocity' end whose velocity is zero (both no-slip for the fluid). The
  !! ends of a window are neither: they move with the particles (docs/model.md §5).
  pure function ends_at_rest(sim) result(rest)
    type(simulation_t), intent(in) :: sim
    logical :: rest(2)
    rest = [at_rest(sim%bc%lower), at_rest(sim%bc%upper)] .and. .not. sim%window_on
  contains
    pure logical function at_rest(kind)
      integer, intent(in) :: kind
      at_rest = kind == END_WALL .or. (kind == END_VELOCITY .and. sim%bc%u_in == 0.0_wp)
    end function at_rest
  end function ends_at_rest

  !> Why the run must stop ('' if it need not): a particle left the lattice (its centre beyond
  !! a side or an end), a prescribed particle reached a wall, a prescribed particle entered
  !! another body: a fixed or prescribed one at contact, a free one deeper than the larger
  !! radius (a free particle normally makes way; one pinned against a wall cannot), or a free
  !! particle came within collision.range (at least a spacing) of an open or moving end (no E11
  !! holds it there, and the flow through the end would blow up around it; docs/model.md §4).
  !! The input check refuses what a constant prescribed velocity makes predictable; this
  !! catches what it cannot (a moving window, free particles). Each owner checks its own
  !! particles, here for the first failing one of this slab; survey_step finds the lowest
  !! particle number over the slabs and sends its message to every rank, so every rank stops
  !! with the same failure at the same step.
  subroutine check_particle_places(sim, n, id, failure)
    type(simulation_t), intent(in) :: sim
    integer, intent(in) :: n
    integer, intent(out) :: id !! the failing particle of this slab, huge(0) if none
    character(len=:), allocatable, intent(out) :: failure !! why, on the rank that owns it
    real(wp) :: nx, ny, y0, dist, reach, near
    integer :: k, m
    character(len=:), allocatable :: what, advice
    character(len=160) :: where
    logical :: walls_x, wall_lo, wall_hi, open_lo, open_hi
    nx = real(sim%lp%nx, wp)
    ny = real(sim%dom%ny, wp)
    walls_x = sim%cfg%domain%sides_kind == END_WALL
    wall_lo = sim%cfg%domain%lower_kind == END_WALL .and. .not. sim%window_on
    wall_hi = sim%cfg%domain%upper_kind == END_WALL .and. .not. sim%window_on
    ! (periodic ends take no particles: the input refuses them)
    associate (rest => ends_at_rest(sim))
      open_lo = .not. (rest(1) .or. sim%window_on)
      open_hi = .not. (rest(2) .or. sim%window_on)
    end associate
    ! docs/model.md §4: the contact range, at least a spacing (a surface past the end row's nodes
    ! makes the flow through the end blow up within a few steps)
    near = max(sim%parts%range, 1.0_wp)
    failure = ''
    id = huge(0)
    do k = 1, sim%parts%n
      if (sim%parts%home(k) /= sim%dom%rank) cycle
      what = ''
      advice = ''
      associate (p => sim%parts%p)
        ! (first: an ordered comparison with NaN traps in the checked build)
        if (.not. (ieee_is_finite(p%x(k)) .and. ieee_is_finite(p%y(k)))) then
          what = 'its centre is not a finite number (the flow or the particle state is not)'
        else if (p%x(k) < 0.0_wp .or. p%x(k) > nx) then
          what = 'its centre left the channel through a side'
        else if (p%y(k) < 0.0_wp) then
          what = 'its centre passed the lower end'//trim(merge(' of the window', '              ', &
                                                               sim%window_on))
        else if (p%y(k) > ny) then
          what = 'its centre passed the upper end'//trim(merge(' of the window', '              ', &
                                                               sim%window_on))
        else if (p%motion(k) == MOTION_PRESCRIBED) then
          if (walls_x .and. (p%x(k) < p%r(k) .or. p%x(k) > nx - p%r(k))) &
            what = 'it reached a side wall'
          if (wall_lo .and. p%y(k) < p%r(k)) what = 'it reached the lower end'
          if (wall_hi .and. p%y(k) > ny - p%r(k)) what = 'it reached the upper end'
          do m = 1, sim%parts%n
            if (m == k) cycle
            dist = hypot(p%x(k) - p%x(m), p%y(k) - p%y(m))
            reach = p%r(k) + p%r(m)
            if (p%motion(m) == MOTION_FREE) reach = max(p%r(k), p%r(m))
            if (dist < reach) what = 'it entered particle '//itoa(p%id(m))
          end do
        else if (p%motion(k) == MOTION_FREE) then
          if (open_lo .and. p%y(k) - p%r(k) < near) what = open_end('lower', sim%bc%lower)
          if (open_hi .and. ny - p%y(k) - p%r(k) < near) what = open_end('upper', sim%bc%upper)
          if (len(what) > 0) advice = 'Close that end (a ''wall'', or a ''velocity'' end '// &
                                      'with &inlet velocity = 0: E11 holds the particle '// &
                                      'there), make the channel longer (&domain height)'
        end if
        if (len(what) == 0) cycle
        if (len(advice) == 0) advice = 'Change its velocity or start (&particles u, v, x, y '// &
                                       'of particle '//itoa(p%id(k))//')'
        y0 = 0.0_wp
        if (sim%window_on) y0 = window_offset(sim%win, sim%lp%dx)
        write (where, '(a,es12.5,a,es12.5,a,i0,a,es12.5,a)') ' at (x, y) = (', &
          p%x(k)*sim%lp%dx, ',', p%y(k)*sim%lp%dx + y0, ') cm, step ', n, ' (t = ', &
          n*sim%lp%dt, ' s)'
        id = p%id(k)
      end associate
      failure = trim(sim%cfg%file)//': particle '//itoa(id)//' (motion = '// &
                quoted_motion(sim%cfg%particles%motion(id))//'): '//what//trim(where)// &
                '; the run stops. '//advice//', or end the run earlier'
      exit
    end do
  contains
    !> 'its surface came within .. spacings of the lower end (an open end, ...)'
    function open_end(which, kind) result(s)
      character(len=*), intent(in) :: which
      integer, intent(in) :: kind
      character(len=:), allocatable :: s
      if (kind == END_OUTFLOW) then
        s = 'an open end, &domain '//which//' = ''outflow'''
      else
        s = 'a moving end, &domain '//which//' = ''velocity'' with &inlet velocity = '// &
            fmt_real(sim%cfg%inlet%velocity)//' cm/s'
      end if
      s = 'its surface came within '//fmt_real(near)//' lattice spacings (collision.range, '// &
          'at least 1) of the '//which//' end ('//s//': no wall force E11 holds it there)'
    end function open_end

    function quoted_motion(m) result(q)
      character(len=*), intent(in) :: m
      character(len=:), allocatable :: q
      q = ''''//trim(m)//''''
    end function quoted_motion
  end subroutine check_particle_places

  !> docs/model.md §5: move the window (the new populations in f_next) with the lowest particle.
  !! A particle near its upper end is found by survey_step, which grows it (grow_window).
  subroutine follow_particles(sim)
    type(simulation_t), intent(inout) :: sim
    integer :: shift
    shift = sim%win%shift
    call window_follow(sim%win, sim%dom, sim%parts, sim%f_next, settle_rows)
    ! the particles moved up with the rows: some may now belong to, or reach, another slab
    if (sim%win%shift /= shift .and. sim%particles_move) &
      call particles_exchange(sim%parts, sim%dom)
  contains
    !> Before the rows move: the interior nodes left for later, on the rows they are on
    subroutine settle_rows()
      call settle_next(sim)
    end subroutine settle_rows
  end subroutine follow_particles

  !> The interior nodes left for later (simulation_settle) reset on f_next, where the populations
  !! are between the sweep and the swap: before the rows move under the disks.
  subroutine settle_next(sim)
    type(simulation_t), intent(inout) :: sim
    if (.not. sim%interior_due) return
    ! (timed in the part that moves the rows)
    call links_interior_after_move(sim%links, sim%parts, sim%dom, sim%f_next)
    sim%interior_due = .false.
  end subroutine settle_next

  !> What every rank must know of the slabs' own particles after a step, found in one reduction
  !! (particles_min; docs/design.md, "Particles across slabs"): the first particle past the
  !! window's margin, the first out of place (check_particle_places), the first faster than
  !! run.particle_speed_limit (sim%fast), and the centres of particles 1 and 2 (sim%pair_v, the
  !! pair diagnostics). "First" is the lowest particle number, so the answer is that of one rank.
  !! A failure's message then comes from the rank that owns the particle (particles_agree). A
  !! window that grows (grow_window) changes the lattice the places are judged on: they are
  !! judged again after it.
  subroutine survey_step(sim, n, failure)
    type(simulation_t), intent(inout) :: sim
    integer, intent(in) :: n
    character(len=:), allocatable, intent(out) :: failure
    ! the entries of the reduction: ids (exact in 8 bytes), a flag, the pair's x, y, r
    integer, parameter :: S_ESCAPE = 1, S_PLACE = 2, S_FAST = 3, S_FINITE = 4, S_PAIR = 5
    real(wp) :: v(S_PAIR + 5)
    integer :: k, m, escaped, place_id, fast_id, ny
    failure = ''
    sim%fast = ''
    if (.not. (sim%particles_move .or. sim%pair_on .or. sim%window_on)) return
    escaped = huge(0)
    place_id = huge(0)
    fast_id = huge(0)
    if (sim%window_on) escaped = particles_first_above_own(sim%parts, sim%dom, &
                                                           window_escape_line(sim%win, sim%dom%ny))
    if (sim%particles_move) then
      call check_particle_places(sim, n, place_id, failure)
      call check_particle_speeds(sim, n, fast_id, sim%fast)
    end if
    v = huge(1.0_wp)
    v(S_ESCAPE:S_FAST) = real([escaped, place_id, fast_id], wp)
    v(S_FINITE) = 1.0_wp
    if (sim%pair_on) then
      ! particles 1 and 2 from their owners (the held particles are in ascending id)
      do k = 1, sim%parts%n
        if (sim%parts%p%id(k) > 2) exit
        if (sim%parts%home(k) /= sim%dom%rank) cycle
        associate (p => sim%parts%p)
          m = S_PAIR + 3*(p%id(k) - 1)
          v(m:m + 2) = [p%x(k), p%y(k), p%r(k)]
          ! (a minimum with NaN depends on the order of the ranks: a flag carries it)
          if (.not. all(ieee_is_finite(v(m:m + 2)))) v(S_FINITE) = 0.0_wp
        end associate
      end do
    end if
    call particles_min(sim%parts, v)
    if (sim%pair_on) then
      sim%pair_v = reshape(v(S_PAIR:S_PAIR + 5), [3, 2])
      if (v(S_FINITE) < 1.0_wp) sim%pair_v = ieee_value(1.0_wp, ieee_quiet_nan)
    end if
    ny = sim%dom%ny
    escaped = nint(v(S_ESCAPE))
    if (sim%window_on .and. escaped /= huge(0)) call grow_window(sim, n, escaped)
    if (sim%particles_move .and. sim%dom%ny /= ny) then
      ! the places on the grown lattice (the window's growth is rare: a reduction of its own)
      call check_particle_places(sim, n, place_id, failure)
      call particles_agree(sim%parts, place_id, failure)
    else if (sim%particles_move) then
      call particles_agree(sim%parts, place_id, failure, lowest=nint(v(S_PLACE)))
    end if
    ! the speed guard speaks only when every particle is in place
    if (sim%particles_move .and. len(failure) == 0) then
      call particles_agree(sim%parts, fast_id, sim%fast, lowest=nint(v(S_FAST)))
    else
      sim%fast = ''
    end if
  end subroutine survey_step

  !> The particle speed guard (run.particle_speed_limit) over this slab's own particles: the
  !! first that fails, huge(0) and '' if none.
  subroutine check_particle_speeds(sim, n, id, fast)
    type(simulation_t), intent(in) :: sim
    integer, intent(in) :: n
    integer, intent(out) :: id
    character(len=:), allocatable, intent(out) :: fast
    real(wp) :: y0
    integer :: k
    fast = ''
    id = huge(0)
    y0 = 0.0_wp
    if (sim%window_on) y0 = window_offset(sim%win, sim%lp%dx)
    do k = 1, sim%parts%n
      if (sim%parts%home(k) /= sim%dom%rank) cycle
      associate (p => sim%parts%p)
        fast = guard_particle_speed([p%u(k)], [p%v(k)], [p%x(k)], [p%y(k)], &
                                    sim%cfg%run%particle_speed_limit, n, n*sim%lp%dt, &
                                    sim%lp%dx, y0, id=p%id(k))
        if (len(fast) > 0) then
          id = p%id(k)
          exit
        end if
      end associate
    end do
  end subroutine check_particle_speeds

  !> A particle (the first by number, `k`) came within window.margin of the window's upper
  !! end: the window grows while it can (window.max_above), or the run ends after this step
  !! (sim%stopped_early says why).
  subroutine grow_window(sim, n, k)
    type(simulation_t), intent(inout) :: sim
    integer, intent(in) :: n
    integer, intent(inout) :: k
    character(len=400) :: msg
    character(len=:), allocatable :: key, why
    real(wp) :: limit
    do while (k > 0 .and. sim%dom%ny < sim%lp%ny_max)
      call simulation_grow(sim, min(sim%lp%ny_max, sim%dom%ny + sim%lp%grow_rows))
      write (msg, '(a,i0,a,f0.2,a,i0,a,i0,a)') 'window grown to ', sim%dom%ny, ' rows (above = ', &
        window_above(sim), ' D_1) at step ', n, ': particle ', k, &
        ' came within window.margin of its upper end'
      call log_line(trim(msg))
      k = window_escaped(sim%win, sim%dom, sim%parts, sim%dom%ny)
    end do
    if (k > 0) then
      ! a window of fixed length, or one grown to its limit: the key that would hold the pair
      key = 'above'
      limit = sim%cfg%window%above
      why = ': the particles separated by more than the window holds ('
      if (sim%cfg%window%max_above > 0.0_wp) then
        key = 'max_above'
        limit = sim%cfg%window%max_above
        why = ', and the window has grown to its limit ('
      else if (sim%cfg%window%max_above < 0.0_wp) then
        ! the limit of its own: the particles outran the velocity scale it is measured with
        key = 'max_above'
        limit = window_above(sim)
        why = ', and the window has grown to the limit window.max_above = -1 sets, faster '// &
              'than the scene''s velocity scale ('
      end if
      write (msg, '(a,i0,a,i0,a,es11.4,a,f7.2,a)') 'particle ', k, &
        ' came within window.margin of the window''s upper end at step ', n, ' (t = ', &
        n*sim%lp%dt, ' s)'//why//'window.'//key//' = ', limit, ' D_1); the run ends '// &
        'here. Raise window.'//key//' to follow them further'
      sim%stopped_early = trim(msg)
    end if
  end subroutine grow_window

  !> The window's length (D_1) above the mark window.below D_1 over its lower end, where it
  !! holds the lowest free centre: window.above, more once it has grown.
  pure real(wp) function window_above(sim) result(above)
    type(simulation_t), intent(in) :: sim
    above = real(sim%dom%ny, wp)*sim%lp%dx/sim%lp%largest_diameter - sim%cfg%window%below
  end function window_above

  !> The window grows to ny rows at its upper end (docs/model.md §5, window.max_above): the
  !! rows are split again over the same ranks (domain_resize), the populations of rows 1..old
  !! ny move to the ranks that now hold them (domain_move_rows), and the new rows at the top
  !! are copies of the old upper end row (domain_fill_new_rows: the outflow's zero gradient,
  !! not fluid at rest, which would stop the outflow at once). The lattices, the sweep's row
  !! buffers and the particles' per-row sums are sized anew; the caller finds the boundary
  !! links (links_find). Called between the sweep and the swap, where f_next holds
  !! the current populations (f as well in place), or at a resume before the checkpoint's
  !! populations are read. Every rank decides a growth from the same particle state and every
  !! row keeps its values, so the bits do not depend on the decomposition.
  subroutine simulation_grow(sim, ny)
    type(simulation_t), intent(inout) :: sim
    integer, intent(in) :: ny
    call move_slabs(sim, ny)
  end subroutine simulation_grow

  !> Every run.balance_every steps (particles on more than one rank): when the costliest slab's
  !! modelled work exceeds run.balance_threshold times the mean, the slab borders move to the
  !! split that balances it (dkt_balance), and the log says so. Called after the survey and
  !! before the links are found, between the sweep and the swap; the interior nodes left for
  !! later are reset first, on the slabs that hold them. Every split gives the same bits.
  subroutine balance_step(sim, n)
    type(simulation_t), intent(inout) :: sim
    integer, intent(in) :: n
    integer :: starts(0:sim%dom%nranks), old(0:sim%dom%nranks)
    real(wp) :: before, after
    if (sim%cfg%run%balance_every == 0 .or. sim%dom%nranks == 1 .or. .not. sim%particles_on) &
      return
    ! (the first step of a run or a resumption is checked too: a scene starts unbalanced)
    if (mod(n, sim%cfg%run%balance_every) /= 0 .and. sim%balance_checked) return
    sim%balance_checked = .true.
    call timer_start(PART_PARTICLES)
    call balance_plan(sim%links, sim%parts, sim%dom, sim%parts%substeps, sim%min_rows, &
                      sim%cfg%run%balance_threshold, starts, before, after)
    if (any(starts /= sim%dom%starts)) then
      old = sim%dom%starts
      call move_slabs(sim, sim%dom%ny, starts)
      if (.not. sim%particles_move) call links_find(sim%links, sim%parts, sim%dom)
      call log_line(balance_line(n, old, starts, before, after))
    else if (before > sim%cfg%run%balance_threshold .and. .not. sim%balance_noted) then
      sim%balance_noted = .true.
      call log_line(balance_line(n, starts, starts, before, after)//'; no split into slabs '// &
                    'of at least '//itoa(sim%min_rows)//' rows is better by 2 % (said once)')
    end if
    call timer_stop(PART_PARTICLES)
  end subroutine balance_step

  !> The slabs move to `ny` rows, split evenly, or split at the borders `starts` (the same
  !! rows, a balanced split): the populations of every row move to the ranks that now hold
  !! it (domain_move_rows), the rows a growth adds are filled (domain_fill_new_rows), the
  !! lattices and the sweep's row buffers are sized anew and the particles are held anew. Called
  !! between the sweep and the swap, where f_next holds the current populations (f as well in
  !! place), or at a resume before the checkpoint's populations are read.
  subroutine move_slabs(sim, ny, starts)
    type(simulation_t), intent(inout) :: sim
    integer, intent(in) :: ny
    integer, intent(in), optional :: starts(0:)
    type(domain_t) :: old
    type(lattice_t) :: grown
    logical :: single, shifted, arith4, half
    call settle_next(sim)
    old = sim%dom
    single = sim%f_next%single
    shifted = sim%f_next%shifted
    arith4 = sim%f_next%arith4
    half = sim%f_next%half
    if (present(starts)) then
      call domain_split(sim%dom, starts)
    else
      call domain_resize(sim%dom, ny)
    end if
    call lattice_allocate(grown, sim%dom%nxp, sim%dom%nyl, single, shifted, arith4, half)
    call domain_move_rows(old, sim%dom, sim%f_next, grown)
    if (sim%dom%ny > old%ny) call domain_fill_new_rows(old, sim%dom, sim%f_next, grown)
    call lattice_free(sim%f)
    if (sim%in_place) then
      sim%f = grown
    else
      call lattice_free(sim%f_next)
      call lattice_allocate(sim%f, sim%dom%nxp, sim%dom%nyl, single, shifted, arith4, half)
    end if
    sim%f_next = grown
    call sweep_init(sim%ws, sim%dom%nxp)
    if (sim%particles_on) call particles_resize_rows(sim%parts, old, sim%dom)
  end subroutine move_slabs

  !> The gap of particles 1 and 2 after step n, for the kissing episodes (docs/model.md §6); every
  !! step, so that no episode falls between two samples of the series.
  subroutine pair_sample(sim, n)
    type(simulation_t), intent(inout) :: sim
    integer, intent(in) :: n
    real(wp) :: gx, gy, gr
    ! particles 1 and 2 from their owners (survey_step)
    associate (v => sim%pair_v)
      call pair_gaps(v(1, 1), v(2, 1), v(3, 1), v(1, 2), v(2, 2), v(3, 2), gx, gy, gr)
    end associate
    call pair_diag_update(sim%pair, n*sim%lp%dt, gr)
  end subroutine pair_sample

  subroutine simulation_finish(sim)
    type(simulation_t), intent(inout) :: sim
    call log_close()
    call lattice_free(sim%f)
    if (.not. sim%in_place) call lattice_free(sim%f_next)
    nullify (sim%f_next%d, sim%f_next%s, sim%f_next%h)
    call domain_free(sim%dom)
  end subroutine simulation_finish

end module dkt_simulation

!> Resolved circular particles (docs/model.md §3): their state, who holds which, and the messages
!> that keep it so (docs/design.md, "Particles across slabs"). The links and bounce-back are
!> dkt_links', the motion and contacts dkt_particle_motion's, the messages dkt_particle_comm's.
!>
!> Lattice units throughout: node (i, j) of global row j sits at (i - 1/2, j - 1/2). A particle
!> is owned by the rank whose rows hold its centre (row j covers y in [j - 1, j)); a rank holds
!> its own particles and a ghost copy of every particle whose disk, widened by the reach `marg`
!> (links, refills and contacts), overlaps its rows. The slabs are at least as thick as the
!> largest disk plus that reach, so a ghost's owner is always a neighbouring slab and every
!> message goes between neighbours:
!>  - after the move, each owner sends the new state of its particles within reach of a
!>    neighbour to that neighbour (particles_exchange): this refreshes the ghosts and migrates a
!>    particle whose centre crossed a slab face;
!>  - each rank sends the per-row force sums of its ghosts' links to their owners, which add them
!>    in global row order (particles_reduce_forces): the same bits on any number of ranks.
!> The local particles are kept in ascending order of their global number `id`, so that every
!> loop over them (links, contacts, refills) takes them in the order one rank would.
module dkt_particles
  use ieee_arithmetic, only: ieee_is_finite
  use dkt_kinds, only: wp, pi, i8
  use dkt_choices, only: MOTION_FREE, MOTION_FIXED, MOTION_PRESCRIBED
  use dkt_domain, only: domain_t, domain_owner_of_row, domain_row_at
  use dkt_cells, only: cells_t
  use dkt_collisions, only: collision_stable_substeps
  use dkt_errors, only: internal_error
  use dkt_text, only: itoa
  use dkt_lubrication, only: lubrication_t
  use dkt_particle_state, only: particle_t, particle_state_t, NPACK, state_fit, state_put, &
                                state_copy, state_copy_first, state_pack, state_unpack, &
                                record_unpack, fit_int, fit_real
  use dkt_particle_comm, only: particle_comm_t, comm_init, comm_start, comm_put, comm_swap, &
                               comm_item, comm_id, comm_min, comm_min_int, comm_agree, &
                               comm_allgather, comm_messages, comm_bytes, SLAB_BELOW, SLAB_ABOVE
  implicit none
  private
  public :: particles_t, particle_t, particles_init, particles_stable_substeps, &
            particles_distribute, particles_exchange, particles_reduce_forces, particles_gather, &
            particles_resize_rows, particles_agree, particles_min, particles_lowest_free, &
            particles_first_above, particles_first_above_own, particles_reach_rows, &
            particles_messages, particles_work, MOTION_FREE, MOTION_FIXED, MOTION_PRESCRIBED

  !> per row-sum entry: particle id, global row, force x, y, torque
  integer, parameter :: NENTRY = 5

  type :: particles_t
    integer :: n = 0                    !! particles held here: own ones and ghosts
    integer :: ntotal = 0               !! particles of the scene
    type(particle_state_t) :: p         !! the n held, ascending id (capacity >= n)
    integer, allocatable :: home(:)     !! the rank that owns disk k of p
    !> E8 moves a free particle by the mean hydrodynamic force and torque of this step and the
    !! last (coupling.average_force): drive_x(k), drive_y(k), drive_torque(k) hold what moves
    !! disk k of p this step
    logical :: average_force = .false.
    real(wp), allocatable :: drive_x(:), drive_y(:), drive_torque(:)
    real(wp) :: gravity = 0             !! g, lattice units, along -y
    real(wp) :: stiffness = 1, stiffness_overlap = 1 !! eps_p, eps'_p, lattice units (E10)
    real(wp) :: range = 1               !! threshold xi (E10), lattice spacings
    !> the lubrication correction (E13; off unless collision.lubrication)
    type(lubrication_t) :: lub
    !> the gap within which a partner or a wall acts on a disk: the contact range, or the
    !! lubrication cut-off when that is larger
    real(wp) :: partner_range = 1
    integer :: substeps = 1
    integer, private :: substeps_needed = 1 !! particles_stable_substeps, over every particle
    real(wp) :: rmax = 0                !! the largest radius
    real(wp), private :: marg = 3       !! the reach beyond a disk within which a slab holds it
    !> the centres at the start of the step in cells of side 2 rmax + range, for the contacts
    type(cells_t) :: cells
    ! the state before the move (refill), and the merge of the exchange, grown as needed
    integer :: nold = 0
    type(particle_state_t) :: old
    type(particle_state_t), private :: merged
    integer, allocatable, private :: mhome(:)
    !> the messages between neighbouring slabs and the particles' collectives
    type(particle_comm_t), private :: comm
  end type particles_t

contains

  !> Set up the particles from centres, radii, velocities (lattice units) and motion modes, every
  !! rank from the whole scene; each then keeps its own and its ghosts (particles_distribute).
  subroutine particles_init(ps, dom, x, y, r, u, v, omega, density_ratio, motion, gravity, &
                            stiffness, stiffness_overlap, range, substeps, average_force, lub)
    type(particles_t), intent(out) :: ps
    type(domain_t), intent(in) :: dom
    real(wp), intent(in) :: x(:), y(:), r(:), u(:), v(:), omega(:), density_ratio(:)
    integer, intent(in) :: motion(:), substeps
    real(wp), intent(in) :: gravity, stiffness, stiffness_overlap, range
    logical, intent(in), optional :: average_force  !! coupling.average_force
    type(lubrication_t), intent(in), optional :: lub !! collision.lubrication and its keys
    type(particle_t), allocatable :: all(:)
    integer :: k
    ps%ntotal = size(x)
    allocate (all(ps%ntotal))
    do k = 1, ps%ntotal
      all(k)%id = k
      all(k)%x = x(k)
      all(k)%y = y(k)
      all(k)%r = r(k)
      all(k)%density_ratio = density_ratio(k)
      all(k)%motion = motion(k)
      all(k)%mass = density_ratio(k)*pi*r(k)**2
      all(k)%inertia = 0.5_wp*all(k)%mass*r(k)**2
      if (motion(k) /= MOTION_FIXED) then
        all(k)%u = u(k)
        all(k)%v = v(k)
        all(k)%omega = omega(k)
      end if
    end do
    ps%gravity = gravity
    ps%stiffness = stiffness
    ps%stiffness_overlap = stiffness_overlap
    ps%range = range
    ps%substeps = substeps
    ps%rmax = max(0.0_wp, maxval(r))
    if (present(lub)) ps%lub = lub
    ps%partner_range = range
    if (ps%lub%on) ps%partner_range = max(range, ps%lub%cutoff)
    ps%marg = particles_reach(ps%rmax, ps%partner_range)
    ps%substeps_needed = collision_stable_substeps(all%r, all%mass, all%motion == MOTION_FREE, &
                                                   stiffness, stiffness_overlap, range)
    call comm_init(ps%comm, dom)
    if (present(average_force)) ps%average_force = average_force
    call particles_distribute(ps, dom, all)
  end subroutine particles_init

  !> The reach beyond a disk of radius rmax or less within which a slab must hold it: its links
  !! (nodes within r + 1.5 of the centre), the nodes it uncovers and the contact partners of the
  !! slab's own particles (within r + rmax + range), with a spacing to spare.
  pure real(wp) function particles_reach(rmax, range) result(marg)
    real(wp), intent(in) :: rmax, range
    marg = max(2.0_wp, rmax + max(range, 0.0_wp)) + 1.0_wp
  end function particles_reach

  !> The fewest rows a slab may have so that a particle held by a slab as a ghost is always owned
  !! by a neighbouring slab: more than the largest disk with its reach (particles_reach).
  pure integer function particles_reach_rows(rmax, range) result(rows)
    real(wp), intent(in) :: rmax, range
    rows = floor(rmax + particles_reach(rmax, range)) + 1
  end function particles_reach_rows

  !> The particle sub-steps per fluid step that the stiffest contact needs, found over every
  !! particle of the scene at the start (dkt_collisions' collision_stable_substeps).
  pure integer function particles_stable_substeps(ps) result(n)
    type(particles_t), intent(in) :: ps
    n = ps%substeps_needed
  end function particles_stable_substeps

  !> The rank that owns a particle: the one whose rows hold its centre (node row j covers
  !! y in [j - 1, j)); a centre that is not finite stays with `keep`. Every rank computes the
  !! same answer from the same state.
  pure integer function owner_of(y, dom, keep) result(r)
    real(wp), intent(in) :: y !! the centre's height
    type(domain_t), intent(in) :: dom
    integer, intent(in) :: keep
    r = keep
    if (.not. ieee_is_finite(y)) return
    r = domain_owner_of_row(dom, domain_row_at(dom, y))
  end function owner_of

  !> Whether this slab (rows y0 + 1 .. y0 + nyl, y in [y0, y0 + nyl)) holds a particle: its
  !! disk (centre height y, radius r) widened by marg overlaps the slab.
  pure logical function held(ps, dom, y, r)
    type(particles_t), intent(in) :: ps
    type(domain_t), intent(in) :: dom
    real(wp), intent(in) :: y, r
    ! (a centre that is not finite is held by its owner alone; tested first: an ordered
    ! comparison with NaN traps in the checked build)
    held = ieee_is_finite(y)
    if (held) held = y + (r + ps%marg) > real(dom%y0, wp) .and. &
                     y - (r + ps%marg) < real(dom%y0 + dom%nyl, wp)
  end function held

  !> Keep of the whole scene `all` (ascending id) the particles this slab holds: its own and the
  !! ghosts within reach. No message: every rank has `all` (the scene, a checkpoint, a gather).
  subroutine particles_distribute(ps, dom, all)
    type(particles_t), intent(inout) :: ps
    type(domain_t), intent(in) :: dom
    type(particle_t), intent(in) :: all(:)
    integer :: k, n
    n = 0
    do k = 1, size(all)
      if (held(ps, dom, all(k)%y, all(k)%r) .or. owner_of(all(k)%y, dom, 0) == dom%rank) n = n + 1
    end do
    call state_fit(ps%p, n)
    call fit_int(ps%home, n)
    n = 0
    do k = 1, size(all)
      if (held(ps, dom, all(k)%y, all(k)%r) .or. owner_of(all(k)%y, dom, 0) == dom%rank) then
        n = n + 1
        call state_put(ps%p, n, all(k))
        ps%home(n) = owner_of(all(k)%y, dom, 0)
      end if
    end do
    ps%n = n
  end subroutine particles_distribute

  !> After the owners moved their particles (or the window moved all of them): each owner sends
  !! the particles within reach of a neighbouring slab to it, and every slab then holds its own
  !! particles as they are now and fresh ghosts. A particle whose centre entered a neighbour's
  !! rows is owned there from now on (migration). One that moved farther than a neighbour's
  !! slab in one step (the speed guard stops such a run) stays with its owner.
  subroutine particles_exchange(ps, dom)
    type(particles_t), intent(inout) :: ps
    type(domain_t), intent(in) :: dom
    integer :: k, md, mu, a, b, c, n, pick
    real(wp) :: lo, hi, v(NPACK)
    lo = real(dom%y0, wp)
    hi = real(dom%y0 + dom%nyl, wp)
    ! the own particles within reach of the slab below, of the slab above
    call comm_start(ps%comm, NPACK)
    do k = 1, ps%n
      if (ps%home(k) /= dom%rank) cycle
      if (.not. ieee_is_finite(ps%p%y(k))) cycle
      if (dom%below >= 0 .and. ps%p%y(k) - (ps%p%r(k) + ps%marg) < lo) then
        call state_pack(ps%p, k, v)
        call comm_put(ps%comm, SLAB_BELOW, v)
      end if
      if (dom%above >= 0 .and. ps%p%y(k) + (ps%p%r(k) + ps%marg) > hi) then
        call state_pack(ps%p, k, v)
        call comm_put(ps%comm, SLAB_ABOVE, v)
      end if
    end do
    call comm_swap(ps%comm, md, mu)
    ! nothing came and every particle held is an own one that stays (one rank, or a slab without
    ! ghosts): the merge below would copy them all in their order, so only their owners change
    if (md == 0 .and. mu == 0) then
      do a = 1, ps%n
        if (ps%home(a) /= dom%rank) exit
        if (.not. held_or_own(a)) exit
      end do
      if (a > ps%n) then
        do a = 1, ps%n
          ps%home(a) = new_owner(ps%p%y(a), dom%rank)
        end do
        return
      end if
    end if
    ! merge by id: the own particles this slab still holds, those from below, those from above
    ! (each list ascending; every particle is owned by one rank, so no id comes twice)
    call state_fit(ps%merged, ps%n + md + mu)
    call fit_int(ps%mhome, ps%n + md + mu)
    n = 0
    a = 1
    b = 1
    c = 1
    do
      do while (a <= ps%n)
        if (ps%home(a) == dom%rank .and. held_or_own(a)) exit
        a = a + 1
      end do
      pick = 0
      if (a <= ps%n) pick = 1
      if (b <= md) then
        if (pick == 0) then
          pick = 2
        else if (comm_id(ps%comm, SLAB_BELOW, b) < ps%p%id(a)) then
          pick = 2
        end if
      end if
      if (c <= mu) then
        if (pick == 0) then
          pick = 3
        else if (comm_id(ps%comm, SLAB_ABOVE, c) < id_of(pick)) then
          pick = 3
        end if
      end if
      if (pick == 0) exit
      n = n + 1
      select case (pick)
      case (1)
        call state_copy(ps%merged, n, ps%p, a)
        ps%mhome(n) = new_owner(ps%p%y(a), dom%rank)
        a = a + 1
      case (2)
        call state_unpack(comm_item(ps%comm, SLAB_BELOW, b), ps%merged, n)
        ps%mhome(n) = new_owner(ps%merged%y(n), dom%below)
        b = b + 1
      case default
        call state_unpack(comm_item(ps%comm, SLAB_ABOVE, c), ps%merged, n)
        ps%mhome(n) = new_owner(ps%merged%y(n), dom%above)
        c = c + 1
      end select
    end do
    call state_copy_first(ps%p, ps%merged, n)
    call fit_int(ps%home, n)
    ps%home(1:n) = ps%mhome(1:n)
    ps%n = n
  contains
    !> Whether own particle a stays here: still within reach, or still owned here
    logical function held_or_own(a)
      integer, intent(in) :: a
      held_or_own = held(ps, dom, ps%p%y(a), ps%p%r(a)) .or. &
                    new_owner(ps%p%y(a), dom%rank) == dom%rank
    end function held_or_own
    !> The id at the head of list `which` (1: own, 2: from below)
    integer function id_of(which)
      integer, intent(in) :: which
      if (which == 1) then
        id_of = ps%p%id(a)
      else
        id_of = comm_id(ps%comm, SLAB_BELOW, b)
      end if
    end function id_of
    !> The owner after the move of a particle owned by `was`: the slab that holds its centre
    !! if that is `was` or a neighbour of it, else still `was`
    integer function new_owner(y, was)
      real(wp), intent(in) :: y !! the centre's height
      integer, intent(in) :: was
      ! (one rank owns every particle)
      if (dom%nranks == 1) then
        new_owner = was
        return
      end if
      new_owner = owner_of(y, dom, was)
      if (abs(new_owner - was) > 1) new_owner = was
    end function new_owner
  end subroutine particles_exchange

  !> E7 totals: each slab sends the per-row sums of its ghosts' links to their owners (the
  !! neighbours), and each owner adds a particle's rows in global row order: those from the slab
  !! below, its own, those from the slab above. Rows without links add nothing, so the total has
  !! the same bits as a sum over every row of the channel, on any number of ranks. Disk k's row
  !! sums are rows(:, e) of local rows rj(e), e = rfirst(k)..rlast(k) (dkt_links).
  subroutine particles_reduce_forces(ps, dom, rfirst, rlast, rj, rows)
    type(particles_t), intent(inout) :: ps
    type(domain_t), intent(in) :: dom
    integer, intent(in) :: rfirst(:), rlast(:), rj(:)
    real(wp), intent(in) :: rows(:, :)
    integer :: k, e, md, mu, b, c, id
    real(wp) :: s(3), entry(NENTRY)
    call comm_start(ps%comm, NENTRY)
    do k = 1, ps%n
      if (ps%home(k) == dom%rank) cycle
      if (rfirst(k) > rlast(k)) cycle
      if (ps%home(k) /= dom%below .and. ps%home(k) /= dom%above) &
        call internal_error('particles_reduce_forces: particle '//itoa(ps%p%id(k))// &
                            ' held by rank '//itoa(dom%rank)//' is owned by rank '// &
                            itoa(ps%home(k))//', not a neighbour')
      do e = rfirst(k), rlast(k)
        entry = [real(ps%p%id(k), wp), real(dom%y0 + rj(e), wp), rows(:, e)]
        if (ps%home(k) == dom%below) then
          call comm_put(ps%comm, SLAB_BELOW, entry)
        else
          call comm_put(ps%comm, SLAB_ABOVE, entry)
        end if
      end do
    end do
    call comm_swap(ps%comm, md, mu)
    call fit_real(ps%drive_x, ps%n)
    call fit_real(ps%drive_y, ps%n)
    call fit_real(ps%drive_torque, ps%n)
    b = 1
    c = 1
    do k = 1, ps%n
      if (ps%home(k) /= dom%rank) cycle
      id = ps%p%id(k)
      s = 0.0_wp
      ! the rows below this slab (ascending, as the slab below sends them), then its own
      do while (b <= md)
        if (comm_id(ps%comm, SLAB_BELOW, b) > id) exit
        if (comm_id(ps%comm, SLAB_BELOW, b) == id) then
          entry = comm_item(ps%comm, SLAB_BELOW, b)
          s = s + entry(3:5)
        end if
        b = b + 1
      end do
      do e = rfirst(k), rlast(k)
        s = s + rows(:, e)
      end do
      do while (c <= mu)
        if (comm_id(ps%comm, SLAB_ABOVE, c) > id) exit
        if (comm_id(ps%comm, SLAB_ABOVE, c) == id) then
          entry = comm_item(ps%comm, SLAB_ABOVE, c)
          s = s + entry(3:5)
        end if
        c = c + 1
      end do
      ! E8's drive: the step's force, or its mean with the last step's (the record's force
      ! until now, which travels with the particle and is kept in checkpoints; zero before
      ! the first step)
      if (ps%average_force) then
        ps%drive_x(k) = 0.5_wp*(s(1) + ps%p%fx(k))
        ps%drive_y(k) = 0.5_wp*(s(2) + ps%p%fy(k))
        ps%drive_torque(k) = 0.5_wp*(s(3) + ps%p%torque(k))
      else
        ps%drive_x(k) = s(1)
        ps%drive_y(k) = s(2)
        ps%drive_torque(k) = s(3)
      end if
      ps%p%fx(k) = s(1)
      ps%p%fy(k) = s(2)
      ps%p%torque(k) = s(3)
    end do
  end subroutine particles_reduce_forces

  !> Every particle of the scene, ascending id, on every rank: from their owners (output,
  !! checkpoints, a window that grows; not in the time loop's steps).
  subroutine particles_gather(ps, dom, all)
    type(particles_t), intent(in) :: ps
    type(domain_t), intent(in) :: dom
    type(particle_t), allocatable, intent(out) :: all(:)
    real(wp), allocatable :: mine(:), every(:)
    integer :: k, m
    m = count(ps%home(1:ps%n) == dom%rank)
    allocate (mine(NPACK*m))
    m = 0
    do k = 1, ps%n
      if (ps%home(k) /= dom%rank) cycle
      call state_pack(ps%p, k, mine(NPACK*m + 1:NPACK*(m + 1)))
      m = m + 1
    end do
    call comm_allgather(ps%comm, mine, every)
    if (size(every) /= NPACK*ps%ntotal) &
      call internal_error('particles_gather: '//itoa(size(every)/NPACK)//' particles owned, '// &
                          'of '//itoa(ps%ntotal))
    allocate (all(ps%ntotal))
    do k = 1, ps%ntotal
      m = nint(every(NPACK*(k - 1) + 1))
      call record_unpack(every(NPACK*(k - 1) + 1:NPACK*k), all(m))
    end do
  end subroutine particles_gather

  !> The slab now holds dom%nyl rows of a channel of dom%ny (a window that grew, docs/model.md
  !! §5): the particles are gathered with the old rows and held anew. The caller finds the
  !! links again (dkt_links' links_find).
  subroutine particles_resize_rows(ps, old, dom)
    type(particles_t), intent(inout) :: ps
    type(domain_t), intent(in) :: old, dom
    type(particle_t), allocatable :: all(:)
    call particles_gather(ps, old, all)
    call particles_distribute(ps, dom, all)
  end subroutine particles_resize_rows

  !> Agree on a failure found by some ranks (a particle's id as the key, huge(0) for none;
  !! dkt_particle_comm's comm_agree): `msg` is then the same everywhere.
  subroutine particles_agree(ps, key, msg, lowest)
    type(particles_t), intent(inout) :: ps
    integer, intent(in) :: key
    character(len=:), allocatable, intent(inout) :: msg
    integer, intent(in), optional :: lowest
    call comm_agree(ps%comm, key, msg, lowest)
  end subroutine particles_agree

  !> The element-wise minimum of v over the ranks, in place: the one reduction a step makes for
  !! what every rank must know of the slabs' own particles (dkt_simulation, survey_step).
  subroutine particles_min(ps, v)
    type(particles_t), intent(inout) :: ps
    real(wp), intent(inout) :: v(:)
    call comm_min(ps%comm, v)
  end subroutine particles_min

  !> The lowest centre of a free particle (huge if none), on every rank; `finite` is false when
  !! some centre is not a finite number.
  subroutine particles_lowest_free(ps, dom, lowest, finite)
    type(particles_t), intent(inout) :: ps
    type(domain_t), intent(in) :: dom
    real(wp), intent(out) :: lowest
    logical, intent(out) :: finite
    real(wp) :: v(2)
    integer :: k
    v = [huge(1.0_wp), 1.0_wp]
    do k = 1, ps%n
      if (ps%home(k) /= dom%rank .or. ps%p%motion(k) /= MOTION_FREE) cycle
      if (.not. ieee_is_finite(ps%p%y(k))) then
        v(2) = 0.0_wp
      else
        v(1) = min(v(1), ps%p%y(k))
      end if
    end do
    call comm_min(ps%comm, v)
    lowest = v(1)
    finite = v(2) > 0.0_wp
  end subroutine particles_lowest_free

  !> The lowest id of a particle whose disk reaches above `top` (0 if none), on every rank.
  integer function particles_first_above(ps, dom, top) result(id)
    type(particles_t), intent(inout) :: ps
    type(domain_t), intent(in) :: dom
    real(wp), intent(in) :: top
    id = comm_min_int(ps%comm, particles_first_above_own(ps, dom, top))
    if (id == huge(0)) id = 0
  end function particles_first_above

  !> The lowest id of this slab's own particles whose disk reaches above `top` (huge(0) if none).
  pure integer function particles_first_above_own(ps, dom, top) result(id)
    type(particles_t), intent(in) :: ps
    type(domain_t), intent(in) :: dom
    real(wp), intent(in) :: top
    integer :: k
    id = huge(0)
    do k = 1, ps%n
      if (ps%home(k) /= dom%rank .or. .not. ieee_is_finite(ps%p%y(k))) cycle
      if (ps%p%y(k) + ps%p%r(k) > top) id = min(id, ps%p%id(k))
    end do
  end function particles_first_above_own

  !> The MPI calls the particle messages have made so far: to neighbours and collectives.
  pure function particles_messages(ps) result(calls)
    type(particles_t), intent(in) :: ps
    integer(i8) :: calls(2)
    calls = comm_messages(ps%comm)
  end function particles_messages

  !> This rank's particle messages per step so far: the bytes sent to neighbours per step (over
  !! `steps`), and the particles held now.
  pure function particles_work(ps, steps) result(work)
    type(particles_t), intent(in) :: ps
    integer, intent(in) :: steps
    real(wp) :: work(2)
    work = [real(comm_bytes(ps%comm), wp)/max(steps, 1), real(ps%n, wp)]
  end function particles_work

end module dkt_particles

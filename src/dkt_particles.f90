!> Resolved circular particles (docs/model.md §3): boundary links with the exact circle
!> intersection, curved bounce-back (E6: halfway, Yu, BFL), momentum exchange (E7, and the
!> Galilean-invariant variant), Newton–Euler (E8) with gravity and buoyancy (E9); the short-range
!> forces (E10–E11) come from dkt_collisions.
!>
!> Lattice units throughout: node (i, j) of global row j sits at (i - 1/2, j - 1/2), the side
!> walls at x = 0 and nx. A particle is owned by the rank whose rows hold its centre; every
!> rank keeps a ghost copy of every particle and computes the links in its own rows. The force
!> is summed link by link within a row, the row sums go to the owner, which adds them in
!> global row order and integrates the motion, and the new state goes back to every rank: the
!> trajectory has the same bits whatever the number of ranks (docs/design.md, "Particles across
!> slabs").
!>
!> Interior nodes (coupling.interior): 'solid', they are not fluid: after each sweep they hold
!> the equilibrium at the local particle velocity, and a node the particle uncovers is refilled
!> with the equilibrium at the wall velocity and the mean density of its fluid neighbours.
!> 'fluid', they hold fluid that streams and collides like the rest, bounced back from the inside
!> of the surface on the interior links; nothing is reset or refilled.
!>
!> Every population these routines read or write goes through its unshifted 8-byte value
!> (dkt_store), whatever lbm.precision stores: bounce-back with a moving wall, the equilibria
!> and the density sums are point-wise physics, computed in 8 bytes.
module dkt_particles
  use mpi_f08, only: MPI_Gatherv, MPI_Allgatherv, MPI_Bcast
  use dkt_kinds, only: wp, mpi_wp, pi, cs2
  use dkt_choices, only: MOTION_FREE, MOTION_FIXED, MOTION_PRESCRIBED, BB_HALFWAY, BB_YU, BB_BFL
  use dkt_lattice, only: ex, ey, w, opp, equilibrium
  use dkt_domain, only: domain_t, domain_rows_for, domain_edge_rows
  use dkt_store, only: lattice_t, lattice_get, lattice_set, lattice_get_node, lattice_set_node
  use dkt_collisions, only: collision_force_on
  use dkt_errors, only: internal_error
  use dkt_text, only: itoa
  use dkt_cells, only: cells_t, cells_build, cells_near, cells_box
  implicit none
  private
  public :: particles_t, particle_t, particles_init, particles_find_links, particles_bounce, &
            particles_interior, particles_inner_save, particles_inner_write, &
            particles_reduce_forces, particles_move, particles_solid_field, particles_resize_rows, &
            particles_stable_substeps, MOTION_FREE, MOTION_FIXED, MOTION_PRESCRIBED, &
            BB_HALFWAY, BB_YU, BB_BFL

  !> One rigid disk, lattice units.
  type :: particle_t
    real(wp) :: x = 0, y = 0          !! centre
    real(wp) :: r = 0                 !! radius
    real(wp) :: u = 0, v = 0          !! velocity
    real(wp) :: omega = 0             !! angular velocity (counter-clockwise)
    real(wp) :: density_ratio = 1     !! rho_p / rho_f
    real(wp) :: mass = 0, inertia = 0 !! M = rho_p pi r^2, I = M r^2 / 2 (per unit depth)
    integer :: motion = MOTION_FREE
    real(wp) :: fx = 0, fy = 0, torque = 0    !! hydrodynamic force and torque of the last step
    real(wp) :: cx = 0, cy = 0                !! collision force of the last step
  end type particle_t

  !> An interior link: node x_s of this slab inside particle k whose neighbour x_f = x_s - e_i
  !! is a lattice node outside k.
  type :: inner_link_t
    integer :: k = 0, i = 0, j = 0, d = 0 !! particle, column, local row of x_s, direction i
    real(wp) :: q = 1                     !! fluid fraction of the link x_f -> x_s
    logical :: ff = .false.               !! x_f is a fluid node
    real(wp) :: val = 0                   !! f_i(x_s, t+1), saved before E6
  end type inner_link_t

  type :: particles_t
    integer :: n = 0
    type(particle_t), allocatable :: p(:)
    integer :: scheme = BB_YU
    logical :: galilean = .false.       !! E7 with (e - u_w) (Wen et al. 2014)
    real(wp) :: gravity = 0             !! g, lattice units, along -y
    real(wp) :: stiffness = 1, stiffness_overlap = 1 !! eps_p, eps'_p, lattice units (E10)
    real(wp) :: range = 1               !! threshold xi (E10), lattice spacings
    integer :: substeps = 1
    real(wp) :: rmax = 0                !! the largest radius
    !> the centres in cells, for the contact forces (cells of side 2 rmax + range, the centres
    !! at the start of the step) or for the nodes inside disks (side 2 rmax, the centres now)
    type(cells_t) :: cells
    ! boundary links of this slab, ordered by particle, row, column, direction
    integer :: nlinks = 0
    integer, allocatable :: lp(:), lx(:), ly(:), ld(:)  !! particle, column, local row, direction
    real(wp), allocatable :: lq(:)                      !! fluid fraction of the link
    logical, allocatable :: lff(:)                      !! second fluid node available
    real(wp), allocatable :: rows(:, :, :)              !! (3, nyl, n): per-row force, torque
    ! interior links (coupling.interior = 'fluid' only), ordered like the boundary links
    logical :: fluid_interior = .false.
    integer :: ninner = 0
    type(inner_link_t), allocatable :: inner(:)
    real(wp), allocatable :: rho_first(:), rho_last(:)  !! density of rows 1, nyl (columns 1..nx)
    real(wp), allocatable :: rho_below(:), rho_above(:) !! the same of halo rows 0, nyl+1
  end type particles_t

contains

  !> Set up n particles from centres, radii, velocities (lattice units) and motion modes.
  subroutine particles_init(ps, dom, x, y, r, u, v, omega, density_ratio, motion, scheme, &
                            galilean, gravity, stiffness, stiffness_overlap, range, substeps, &
                            fluid_interior)
    type(particles_t), intent(out) :: ps
    type(domain_t), intent(in) :: dom
    real(wp), intent(in) :: x(:), y(:), r(:), u(:), v(:), omega(:), density_ratio(:)
    integer, intent(in) :: motion(:), scheme, substeps
    logical, intent(in) :: galilean
    real(wp), intent(in) :: gravity, stiffness, stiffness_overlap, range
    logical, intent(in), optional :: fluid_interior !! coupling.interior = 'fluid'
    integer :: k
    ps%n = size(x)
    allocate (ps%p(ps%n))
    do k = 1, ps%n
      ps%p(k)%x = x(k)
      ps%p(k)%y = y(k)
      ps%p(k)%r = r(k)
      ps%p(k)%density_ratio = density_ratio(k)
      ps%p(k)%motion = motion(k)
      ps%p(k)%mass = density_ratio(k)*pi*r(k)**2
      ps%p(k)%inertia = 0.5_wp*ps%p(k)%mass*r(k)**2
      if (motion(k) /= MOTION_FIXED) then
        ps%p(k)%u = u(k)
        ps%p(k)%v = v(k)
        ps%p(k)%omega = omega(k)
      end if
    end do
    ps%scheme = scheme
    ps%galilean = galilean
    ps%gravity = gravity
    ps%stiffness = stiffness
    ps%stiffness_overlap = stiffness_overlap
    ps%range = range
    ps%substeps = substeps
    ps%rmax = max(0.0_wp, maxval(r))
    allocate (ps%rows(3, dom%nyl, ps%n))
    allocate (ps%lp(0), ps%lx(0), ps%ly(0), ps%ld(0), ps%lq(0), ps%lff(0))
    if (present(fluid_interior)) ps%fluid_interior = fluid_interior
    if (ps%fluid_interior) then
      allocate (ps%inner(0))
      allocate (ps%rho_first(dom%nx), ps%rho_last(dom%nx), ps%rho_below(dom%nx), &
                ps%rho_above(dom%nx))
      ps%rho_below = 1.0_wp
      ps%rho_above = 1.0_wp
    end if
  end subroutine particles_init

  !> The fewest particle sub-steps per fluid step for which the explicit update (E8) of the
  !! stiffest contact (E10–E11) stays stable: omega h <= 1, with omega^2 = k / m for the
  !! spring constant k of the overlap or range law at contact and the reduced mass m.
  !! Particles of one kind (radius, mass, free or not) give the same springs, so the pairs are
  !! taken between kinds: linear in the particles for a scene of a few kinds, and the same
  !! value as over all pairs. huge(n) stands for a count too large for an integer.
  pure integer function particles_stable_substeps(ps) result(n)
    type(particles_t), intent(in) :: ps
    real(wp) :: omega, k, m
    integer :: a, b, i, j, nk
    integer, allocatable :: first(:), members(:) !! a particle of each kind, how many there are
    allocate (first(ps%n), members(ps%n))
    nk = 0
    do a = 1, ps%n
      do j = 1, nk
        b = first(j)
        if (ps%p(b)%r == ps%p(a)%r .and. ps%p(b)%mass == ps%p(a)%mass .and. &
            ((ps%p(b)%motion == MOTION_FREE) .eqv. (ps%p(a)%motion == MOTION_FREE))) exit
      end do
      if (j > nk) then
        nk = j
        first(j) = a
        members(j) = 0
      end if
      members(j) = members(j) + 1
    end do
    omega = 0.0_wp
    do i = 1, nk
      a = first(i)
      if (ps%p(a)%motion /= MOTION_FREE) cycle
      ! the wall: the mirror particle at d = 2 r, stiffness halved (E11)
      k = spring(2.0_wp*ps%p(a)%r, 0.5_wp*ps%stiffness, 0.5_wp*ps%stiffness_overlap)
      omega = max(omega, sqrt(k/ps%p(a)%mass))
      do j = 1, nk
        if (j == i .and. members(i) < 2) cycle ! no other particle of this kind
        b = first(j)
        k = spring(ps%p(a)%r + ps%p(b)%r, ps%stiffness, ps%stiffness_overlap)
        m = ps%p(a)%mass
        if (ps%p(b)%motion == MOTION_FREE) m = m*ps%p(b)%mass/(m + ps%p(b)%mass)
        omega = max(omega, sqrt(k/m))
      end do
    end do
    if (omega >= real(huge(n), wp)) then
      n = huge(n)
    else
      n = max(1, ceiling(omega))
    end if
  contains
    !> dF/dgap of E10 at contact: d/eps' in the overlap, up to 2 d xi/eps in the range
    pure real(wp) function spring(d, eps, eps_overlap)
      real(wp), intent(in) :: d, eps, eps_overlap
      spring = max(d/eps_overlap, 2.0_wp*d*ps%range/eps)
    end function spring
  end function particles_stable_substeps

  !> The rigid-body velocity U + Omega x (x - X) of particle p at the point (px, py).
  pure subroutine surface_velocity(p, px, py, ux, uy)
    type(particle_t), intent(in) :: p
    real(wp), intent(in) :: px, py
    real(wp), intent(out) :: ux, uy
    ux = p%u - p%omega*(py - p%y)
    uy = p%v + p%omega*(px - p%x)
  end subroutine surface_velocity

  !> Whether the point (px, py) lies strictly inside particle k.
  pure logical function inside(p, px, py)
    type(particle_t), intent(in) :: p
    real(wp), intent(in) :: px, py
    inside = (px - p%x)**2 + (py - p%y)**2 < p%r**2
  end function inside

  !> The fraction t in (0, 1] of the link from the point (px, py), outside particle p, along
  !! e_d that lies outside p: |x + t e - X|^2 = r^2, the smaller root.
  pure real(wp) function link_fraction(p, px, py, d) result(q)
    type(particle_t), intent(in) :: p
    real(wp), intent(in) :: px, py
    integer, intent(in) :: d
    real(wp) :: dxp, dyp, b, c, t
    dxp = px - p%x
    dyp = py - p%y
    b = dxp*ex(d) + dyp*ey(d)
    c = dxp*dxp + dyp*dyp - p%r*p%r
    t = (-b - sqrt(max(b*b - (ex(d)**2 + ey(d)**2)*c, 0.0_wp)))/(ex(d)**2 + ey(d)**2)
    q = min(max(t, 1.0e-6_wp), 1.0_wp)
  end function link_fraction

  !> The wall point x_w = x_f + q e_d of the link from node (i, jg) (global row) along e_d, the
  !! rigid-body velocity u_w there and the moving-wall term W = -2 w_d rho (e_d . u_w)/c_s^2 of
  !! the population bounced back towards x_f. The interior side of the same link receives -W.
  pure subroutine wall_of_link(p, i, jg, d, q, rho, xw, yw, uwx, uwy, wall)
    type(particle_t), intent(in) :: p
    integer, intent(in) :: i, jg, d
    real(wp), intent(in) :: q, rho
    real(wp), intent(out) :: xw, yw, uwx, uwy, wall
    xw = i - 0.5_wp + q*ex(d)
    yw = jg - 0.5_wp + q*ey(d)
    call surface_velocity(p, xw, yw, uwx, uwy)
    wall = -2.0_wp*w(d)*rho*(ex(d)*uwx + ey(d)*uwy)/cs2
  end subroutine wall_of_link

  !> The density at node (i, j) of this slab, summed as every routine here sums it.
  real(wp) function node_density(f, i, j) result(rho)
    type(lattice_t), intent(in) :: f
    integer, intent(in) :: i, j
    rho = sum(lattice_get_node(f, i, j))
  end function node_density

  !> Whether global node (i, jg) is a fluid node: in the channel and outside every particle.
  !! Only the disks of the cells within rmax of the node are tested: ps%cells must hold the
  !! present centres (place_for_nodes).
  pure logical function is_fluid(ps, dom, i, jg)
    type(particles_t), intent(in) :: ps
    type(domain_t), intent(in) :: dom
    integer, intent(in) :: i, jg
    integer :: k, l, i1, i2, j1, j2, jc
    real(wp) :: px, py
    is_fluid = i >= 1 .and. i <= dom%nx .and. (dom%periodic_y .or. (jg >= 1 .and. jg <= dom%ny))
    if (.not. is_fluid) return
    px = i - 0.5_wp
    py = jg - 0.5_wp
    call cells_box(ps%cells, px, py, ps%rmax, i1, i2, j1, j2)
    if (i1 == 0) then
      is_fluid = .not. any([(inside(ps%p(k), px, py), k=1, ps%n)])
      return
    end if
    associate (c => ps%cells)
      ! the cells i1..i2 of a row of cells hold one run of c%items
      do jc = j1, j2
        do l = c%start(i1 + c%nx*(jc - 1)), c%start(i2 + 1 + c%nx*(jc - 1)) - 1
          if (inside(ps%p(c%items(l)), px, py)) is_fluid = .false.
        end do
      end do
      do l = 1, size(c%stray)
        if (inside(ps%p(c%stray(l)), px, py)) is_fluid = .false.
      end do
    end associate
  end function is_fluid

  !> Place the present centres in cells for is_fluid: a node lies only in disks whose centres
  !! are within rmax of it.
  subroutine place_for_nodes(ps)
    type(particles_t), intent(inout) :: ps
    call cells_build(ps%cells, ps%p%x, ps%p%y, 2.0_wp*ps%rmax)
  end subroutine place_for_nodes

  !> The slab now holds dom%nyl rows (a window that grew, docs/model.md §5): the per-row sums
  !! of E7 take the new row count. The caller finds the links again (particles_find_links).
  subroutine particles_resize_rows(ps, dom)
    type(particles_t), intent(inout) :: ps
    type(domain_t), intent(in) :: dom
    deallocate (ps%rows)
    allocate (ps%rows(3, dom%nyl, ps%n))
    ps%rows = 0.0_wp
  end subroutine particles_resize_rows

  !> Find the boundary links of this slab: fluid node x_f in rows 1..nyl whose neighbour
  !! x_f + e_i lies inside a particle; q in (0, 1] is the fraction of the link in the fluid
  !! (exact intersection of the segment with the circle).
  subroutine particles_find_links(ps, dom)
    type(particles_t), intent(inout) :: ps
    type(domain_t), intent(in) :: dom
    integer :: k, j, jg, i, d, n, cap, i1, i2, j1, j2
    real(wp) :: px, py, dist2, near2, deep2
    call place_for_nodes(ps)
    n = 0
    ps%ninner = 0
    cap = max(16, size(ps%lp))
    call resize(cap)
    do k = 1, ps%n
      associate (p => ps%p(k))
        call box(p, dom, i1, i2, j1, j2)
        ! A node farther than r + 1.5 from the centre has no neighbour (|e_i| <= sqrt 2) inside
        ! p, and one nearer than r - 1.5 has all of them and itself inside p: neither makes a
        ! link of p (nor an interior link: every x_s - e_i is inside p), so only the ring
        ! between is searched, with the same links in the same order
        near2 = (p%r + 1.5_wp)**2
        deep2 = max(p%r - 1.5_wp, 0.0_wp)**2
        do j = j1, j2
          jg = dom%y0 + j
          do i = i1, i2
            px = i - 0.5_wp
            py = jg - 0.5_wp
            dist2 = (px - p%x)**2 + (py - p%y)**2
            if (dist2 >= near2 .or. dist2 < deep2) cycle
            if (.not. is_fluid(ps, dom, i, jg)) then
              if (ps%fluid_interior) then
                if (inside(p, px, py)) call add_inner_links(ps, dom, k, i, j)
              end if
              cycle
            end if
            do d = 1, 8
              if (.not. inside(p, px + ex(d), py + ey(d))) cycle
              n = n + 1
              if (n > cap) then
                cap = 2*cap
                call resize(cap)
              end if
              ps%lp(n) = k
              ps%lx(n) = i
              ps%ly(n) = j
              ps%ld(n) = d
              ps%lq(n) = link_fraction(p, px, py, d)
              ps%lff(n) = is_fluid(ps, dom, i - ex(d), jg - ey(d))
            end do
          end do
        end do
      end associate
    end do
    ps%nlinks = n
  contains
    subroutine resize(m)
      integer, intent(in) :: m
      integer, allocatable :: ti(:)
      real(wp), allocatable :: tr(:)
      logical, allocatable :: tl(:)
      integer :: keep
      keep = min(n, size(ps%lp))
      allocate (ti(m)); ti(1:keep) = ps%lp(1:keep); call move_alloc(ti, ps%lp)
      allocate (ti(m)); ti(1:keep) = ps%lx(1:keep); call move_alloc(ti, ps%lx)
      allocate (ti(m)); ti(1:keep) = ps%ly(1:keep); call move_alloc(ti, ps%ly)
      allocate (ti(m)); ti(1:keep) = ps%ld(1:keep); call move_alloc(ti, ps%ld)
      allocate (tr(m)); tr(1:keep) = ps%lq(1:keep); call move_alloc(tr, ps%lq)
      allocate (tl(m)); tl(1:keep) = ps%lff(1:keep); call move_alloc(tl, ps%lff)
    end subroutine resize
  end subroutine particles_find_links

  !> Append the interior links of node (i, j) of this slab, which lies inside particle k
  !! (coupling.interior = 'fluid'): each direction i with x_f = x_s - e_i outside k and a
  !! lattice node (a fluid node, a halo node or a node of another particle; not beyond a side
  !! or a closed end). q is computed from x_f as for the boundary link (x_f, i), so that both
  !! sides of the link take the wall point, and u_w there, with the same bits.
  subroutine add_inner_links(ps, dom, k, i, j)
    type(particles_t), intent(inout) :: ps
    type(domain_t), intent(in) :: dom
    integer, intent(in) :: k, i, j
    type(inner_link_t), allocatable :: grown(:)
    integer :: d, fi, fjg
    do d = 1, 8
      fi = i - ex(d)
      fjg = dom%y0 + j - ey(d)
      if (inside(ps%p(k), fi - 0.5_wp, fjg - 0.5_wp)) cycle
      if (fi < 1 .or. fi > dom%nx) cycle
      if (.not. dom%periodic_y .and. (fjg < 1 .or. fjg > dom%ny)) cycle
      if (ps%ninner == size(ps%inner)) then
        allocate (grown(max(64, 2*ps%ninner)))
        grown(1:ps%ninner) = ps%inner(1:ps%ninner)
        call move_alloc(grown, ps%inner)
      end if
      ps%ninner = ps%ninner + 1
      ps%inner(ps%ninner) = inner_link_t(k, i, j, d, &
                                         link_fraction(ps%p(k), fi - 0.5_wp, fjg - 0.5_wp, d), &
                                         is_fluid(ps, dom, fi, fjg), 0.0_wp)
    end do
  end subroutine add_inner_links

  !> Interior side of the links (coupling.interior = 'fluid'), first half: with the halo rows
  !! complete and before any boundary link is bounced, save for each interior link (x_s, i)
  !! the population the interior node receives, half-way bounce-back from the inside,
  !!     f_i(x_s, t+1) = f_ibar*(x_s) - W,
  !! W the moving-wall term of the boundary link (x_f, i) (rho the density at x_f it uses, 1
  !! when x_f is not a fluid node). The densities of the halo rows come from their owners, so
  !! a link across a slab face uses the bits its boundary link uses. Every rank calls it.
  subroutine particles_inner_save(ps, dom, f)
    type(particles_t), intent(inout) :: ps
    type(domain_t), intent(in) :: dom
    type(lattice_t), intent(in) :: f
    integer :: l, i, j, d, fi, fj
    real(wp) :: rho, xw, yw, uwx, uwy, wall
    do i = 1, dom%nx
      ps%rho_first(i) = node_density(f, i, 1)
      ps%rho_last(i) = node_density(f, i, dom%nyl)
    end do
    call domain_edge_rows(dom, ps%rho_first, ps%rho_last, ps%rho_below, ps%rho_above)
    do l = 1, ps%ninner
      i = ps%inner(l)%i
      j = ps%inner(l)%j
      d = ps%inner(l)%d
      fi = i - ex(d)
      fj = j - ey(d)
      rho = 1.0_wp
      if (ps%inner(l)%ff) then
        if (fj == 0) then
          rho = ps%rho_below(fi)
        else if (fj == dom%nyl + 1) then
          rho = ps%rho_above(fi)
        else
          rho = node_density(f, fi, fj)
        end if
      end if
      call wall_of_link(ps%p(ps%inner(l)%k), fi, dom%y0 + fj, d, ps%inner(l)%q, rho, xw, yw, &
                        uwx, uwy, wall)
      ps%inner(l)%val = lattice_get(f, i, j, opp(d)) - wall
    end do
  end subroutine particles_inner_save

  !> Interior side, second half: after every boundary link has been bounced (E6 and E7 read
  !! f_i*(x_f) and the density at x_f), write each saved value into slot i of x_f, which only
  !! x_s pulls in the sweep.
  subroutine particles_inner_write(ps, f)
    type(particles_t), intent(in) :: ps
    type(lattice_t), intent(inout) :: f
    integer :: l
    do l = 1, ps%ninner
      associate (a => ps%inner(l))
        call lattice_set(f, a%i - ex(a%d), a%j - ey(a%d), a%d, a%val)
      end associate
    end do
  end subroutine particles_inner_write

  !> E6 and E7 on the links whose fluid node lies in rows j1..j2: write the bounced population
  !! f_ibar(x_f, t+1) into the slot of the solid node that x_f pulls it from, and add the link's
  !! momentum exchange to the sums of rows j1..j2 (restarted here). f holds post-collision
  !! populations, with the ghosts complete and, when j1..j2 touches row 1 or nyl, the halo rows
  !! too. A link reads only fluid nodes (x_f, and x_f - e_i for Yu/BFL) and writes only a solid
  !! slot that no other link reads and only x_f pulls, so links of rows 2..nyl-1 neither read
  !! nor write a halo row, and the links can be taken in row groups while the halo travels.
  subroutine particles_bounce(ps, dom, f, j1, j2)
    type(particles_t), intent(inout) :: ps
    type(domain_t), intent(in) :: dom
    type(lattice_t), intent(inout) :: f
    integer, intent(in) :: j1, j2 !! rows of the fluid nodes whose links are bounced
    integer :: l, k, i, j, d, db
    real(wp) :: q, fi, fib, fff, fb, rho, uwx, uwy, wall, xw, yw, fx, fy
    if (j2 < j1) return
    ps%rows(:, j1:j2, :) = 0.0_wp
    do l = 1, ps%nlinks
      j = ps%ly(l)
      if (j < j1 .or. j > j2) cycle
      k = ps%lp(l)
      i = ps%lx(l)
      d = ps%ld(l)
      db = opp(d)
      q = ps%lq(l)
      associate (p => ps%p(k))
        ! wall point, its velocity u_w = U + Omega x (x_w - X) and the moving-wall term
        rho = node_density(f, i, j)
        call wall_of_link(p, i, dom%y0 + j, d, q, rho, xw, yw, uwx, uwy, wall)
        fi = lattice_get(f, i, j, d)
        fib = lattice_get(f, i, j, db)
        fff = 0.0_wp
        if (ps%lff(l)) fff = lattice_get(f, i - ex(d), j - ey(d), d)
        select case (ps%scheme)
        case (BB_YU)
          if (ps%lff(l)) then
            fb = ((1.0_wp - q)*fff + q*fi + q*fib + wall)/(1.0_wp + q)
          else
            fb = fi + wall
          end if
        case (BB_BFL)
          if (q < 0.5_wp) then
            if (ps%lff(l)) then
              fb = 2.0_wp*q*fi + (1.0_wp - 2.0_wp*q)*fff + wall
            else
              fb = fi + wall
            end if
          else
            fb = (fi + (2.0_wp*q - 1.0_wp)*fib + wall)/(2.0_wp*q)
          end if
        case (BB_HALFWAY)
          fb = fi + wall
        case default
          call internal_error('particles_bounce: bounce-back code '//itoa(ps%scheme))
        end select
        call lattice_set(f, i + ex(d), j + ey(d), db, fb)
        ! E7: F_i = e_i f_i* - e_ibar f_ibar(t+1) = e_i (f_i* + f_ibar); the Galilean-invariant
        ! form replaces e by e - u_w
        fx = ex(d)*(fi + fb)
        fy = ey(d)*(fi + fb)
        if (ps%galilean) then
          fx = fx - uwx*(fi - fb)
          fy = fy - uwy*(fi - fb)
        end if
        ps%rows(1, j, k) = ps%rows(1, j, k) + fx
        ps%rows(2, j, k) = ps%rows(2, j, k) + fy
        ps%rows(3, j, k) = ps%rows(3, j, k) + (xw - p%x)*fy - (yw - p%y)*fx
      end associate
    end do
  end subroutine particles_bounce

  !> The rank that owns a particle: the one whose rows hold its centre (node row j covers
  !! y in [j - 1, j)). Every rank computes the same answer from the same state.
  integer function owner_of(p, dom) result(r)
    type(particle_t), intent(in) :: p
    type(domain_t), intent(in) :: dom
    integer :: jg, y0, nyl
    jg = min(max(floor(p%y) + 1, 1), dom%ny)
    do r = 0, dom%nranks - 1
      call domain_rows_for(dom%ny, dom%nranks, r, y0, nyl)
      if (jg > y0 .and. jg <= y0 + nyl) return
    end do
    r = dom%nranks - 1
  end function owner_of

  !> E7 totals: every rank sends its per-row sums to the particle's owner, which adds them in
  !! global row order, so the total has the same bits on any number of ranks. With everywhere,
  !! every rank receives the sums and adds them in the same order (the same bits), so that no
  !! state needs to be sent back when nothing moves.
  subroutine particles_reduce_forces(ps, dom, everywhere)
    type(particles_t), intent(inout) :: ps
    type(domain_t), intent(in) :: dom
    logical, intent(in) :: everywhere
    real(wp), allocatable :: all(:, :)
    integer :: counts(dom%nranks), displs(dom%nranks)
    integer :: k, r, j, own, y0, nyl
    real(wp) :: s(3)
    do r = 0, dom%nranks - 1
      call domain_rows_for(dom%ny, dom%nranks, r, y0, nyl)
      counts(r + 1) = 3*nyl
      displs(r + 1) = 3*y0
    end do
    allocate (all(3, dom%ny))
    do k = 1, ps%n
      if (everywhere) then
        call MPI_Allgatherv(ps%rows(:, :, k), 3*dom%nyl, mpi_wp, all, counts, displs, mpi_wp, &
                            dom%comm)
      else
        own = owner_of(ps%p(k), dom)
        call MPI_Gatherv(ps%rows(:, :, k), 3*dom%nyl, mpi_wp, all, counts, displs, mpi_wp, &
                         own, dom%comm)
        if (dom%rank /= own) cycle
      end if
      s = 0.0_wp
      do j = 1, dom%ny
        s = s + all(:, j)
      end do
      ps%p(k)%fx = s(1)
      ps%p(k)%fy = s(2)
      ps%p(k)%torque = s(3)
    end do
  end subroutine particles_reduce_forces

  !> After the sweep: interior nodes get the equilibrium at the local particle velocity (they
  !! are not fluid; this keeps them finite and ready for refilling).
  subroutine particles_interior(ps, dom, f)
    type(particles_t), intent(in) :: ps
    type(domain_t), intent(in) :: dom
    type(lattice_t), intent(inout) :: f
    integer :: k, i, j, jg, i1, i2, j1, j2
    real(wp) :: px, py, ux, uy
    do k = 1, ps%n
      associate (p => ps%p(k))
        call box(p, dom, i1, i2, j1, j2)
        do j = j1, j2
          jg = dom%y0 + j
          do i = i1, i2
            px = i - 0.5_wp
            py = jg - 0.5_wp
            if (.not. inside(p, px, py)) cycle
            call surface_velocity(p, px, py, ux, uy)
            call lattice_set_node(f, i, j, equilibrium(1.0_wp, ux, uy))
          end do
        end do
      end associate
    end do
  end subroutine particles_interior

  !> E8–E11: each owner advances its particles by one fluid step (in sub-steps for the contact
  !! forces, the other particles held at their start-of-step positions), prescribed ones by
  !! their given velocity; the owners then send the new states to every rank, which keeps a
  !! ghost copy of every particle. A particle whose centre crossed into another slab has a new
  !! owner from the next step on. Last, the nodes the particles uncovered are refilled.
  !! When every particle is fixed (moving false; the forces were summed on every rank), every
  !! rank computes the contact forces itself from the same state, with the same bits, and
  !! nothing is sent or refilled: no node is uncovered.
  subroutine particles_move(ps, dom, f, end_walls, moving)
    type(particles_t), intent(inout) :: ps
    type(domain_t), intent(in) :: dom
    type(lattice_t), intent(inout) :: f
    logical, intent(in) :: end_walls(2) !! the lower, the upper end is a wall (E11 against it)
    logical, intent(in) :: moving    !! some particle is free or prescribed
    type(particle_t), allocatable :: old(:)
    real(wp) :: h, ax, ay, gy, xs(ps%n), ys(ps%n), rs(ps%n), state(10)
    integer :: k, s, own, m
    integer, allocatable :: near(:)
    allocate (old, source=ps%p)
    h = 1.0_wp/ps%substeps
    ! contact partners (E10) lie within r_k + rmax + range of a centre
    call cells_build(ps%cells, old%x, old%y, 2.0_wp*ps%rmax + ps%range)
    ! contiguous copies, made once: a component array old%r passed on would be copied per call
    xs = old%x
    ys = old%y
    rs = old%r
    do k = 1, ps%n
      own = owner_of(old(k), dom)
      if (own == dom%rank .or. .not. moving) then
        associate (p => ps%p(k))
          do s = 1, ps%substeps
            xs(k) = p%x
            ys(k) = p%y
            call cells_near(ps%cells, xs(k), ys(k), old(k)%r + ps%rmax + ps%range, near, m)
            call collision_force_on(k, xs, ys, rs, real(dom%nx, wp), real(dom%ny, wp), &
                                    end_walls, ps%stiffness, ps%stiffness_overlap, ps%range, &
                                    p%cx, p%cy, near(1:m))
            select case (p%motion)
            case (MOTION_FREE)
              ! E9: weight minus buoyancy, (rho_p - rho_f) pi r^2 g along -y
              gy = -(p%density_ratio - 1.0_wp)*pi*p%r**2*ps%gravity
              ax = (p%fx + p%cx)/p%mass
              ay = (p%fy + p%cy + gy)/p%mass
              ! E8: X += U h + a h^2 / 2, U += a h, Omega += T/I h
              p%x = p%x + p%u*h + 0.5_wp*ax*h*h
              p%y = p%y + p%v*h + 0.5_wp*ay*h*h
              p%u = p%u + ax*h
              p%v = p%v + ay*h
              p%omega = p%omega + p%torque/p%inertia*h
            case (MOTION_PRESCRIBED)
              p%x = p%x + p%u*h
              p%y = p%y + p%v*h
            case (MOTION_FIXED)
            case default
              call internal_error('particles_move: motion code '//itoa(p%motion))
            end select
          end do
          state = [p%x, p%y, p%u, p%v, p%omega, p%fx, p%fy, p%torque, p%cx, p%cy]
          xs(k) = old(k)%x
          ys(k) = old(k)%y
        end associate
      end if
      if (.not. moving) cycle
      call MPI_Bcast(state, size(state), mpi_wp, own, dom%comm)
      associate (p => ps%p(k))
        p%x = state(1); p%y = state(2); p%u = state(3); p%v = state(4); p%omega = state(5)
        p%fx = state(6); p%fy = state(7); p%torque = state(8); p%cx = state(9); p%cy = state(10)
      end associate
    end do
    ! interior fluid (coupling.interior = 'fluid'): an uncovered node already holds fluid
    call place_for_nodes(ps)
    if (moving .and. .not. ps%fluid_interior) call refill(ps, old, dom, f)
  end subroutine particles_move

  !> Nodes inside a particle's old disk and outside every new one become fluid: equilibrium at
  !! the wall velocity there with the mean density of their fluid neighbours.
  subroutine refill(ps, old, dom, f)
    type(particles_t), intent(in) :: ps
    type(particle_t), intent(in) :: old(:)
    type(domain_t), intent(in) :: dom
    type(lattice_t), intent(inout) :: f
    integer :: k, i, j, jg, d, nf, i1, i2, j1, j2
    real(wp) :: px, py, rho, ux, uy
    do k = 1, ps%n
      associate (o => old(k), p => ps%p(k))
        call box(o, dom, i1, i2, j1, j2)
        do j = j1, j2
          jg = dom%y0 + j
          do i = i1, i2
            px = i - 0.5_wp
            py = jg - 0.5_wp
            if (.not. inside(o, px, py)) cycle
            if (.not. is_fluid(ps, dom, i, jg)) cycle
            ! mean density of the fluid neighbours in the same row: a row is never split
            ! between ranks, so the refill does not depend on the decomposition
            rho = 0.0_wp
            nf = 0
            do d = 1, 3, 2
              if (inside(o, px + ex(d), py)) cycle
              if (.not. is_fluid(ps, dom, i + ex(d), jg)) cycle
              rho = rho + sum(lattice_get_node(f, i + ex(d), j))
              nf = nf + 1
            end do
            if (nf > 0) then
              rho = rho/nf
            else
              rho = 1.0_wp
            end if
            call surface_velocity(p, px, py, ux, uy)
            call lattice_set_node(f, i, j, equilibrium(rho, ux, uy))
          end do
        end do
      end associate
    end do
  end subroutine refill

  !> Rows j1..j2 and columns i1..i2 of this slab that a disk can touch, with a margin of two
  !! nodes for the links and their second fluid nodes.
  pure subroutine box(p, dom, i1, i2, j1, j2)
    type(particle_t), intent(in) :: p
    type(domain_t), intent(in) :: dom
    integer, intent(out) :: i1, i2, j1, j2
    i1 = max(1, floor(p%x - p%r) - 2)
    i2 = min(dom%nx, ceiling(p%x + p%r) + 2)
    j1 = max(1, floor(p%y - p%r) - 2 - dom%y0)
    j2 = min(dom%nyl, ceiling(p%y + p%r) + 2 - dom%y0)
  end subroutine box

  !> The particle index at each node of the slab (0 in the fluid), for output.
  subroutine particles_solid_field(ps, dom, id)
    type(particles_t), intent(in) :: ps
    type(domain_t), intent(in) :: dom
    real(wp), intent(out) :: id(:, :)
    integer :: k, i, j, i1, i2, j1, j2
    id = 0.0_wp
    do k = 1, ps%n
      call box(ps%p(k), dom, i1, i2, j1, j2)
      do j = j1, j2
        do i = i1, i2
          if (inside(ps%p(k), i - 0.5_wp, dom%y0 + j - 0.5_wp)) id(i, j) = k
        end do
      end do
    end do
  end subroutine particles_solid_field

end module dkt_particles

!> The boundary links of the disks a slab holds, and everything found from them (docs/model.md
!> §3): the nodes inside each disk as runs of columns per row and their mask, the links with
!> their fractions q, the row-sum entries of E7 and the order by row, the interior links
!> (coupling.interior = 'fluid'), and what the last search found, kept for the next one.
!> `links_t` owns all of it behind private components; its procedures find the links
!> (links_find), bounce the populations on them and sum the momentum exchange (links_bounce),
!> reset the nodes inside the disks (links_interior) and refill those a moving disk uncovers
!> (links_refill). The search is the submodule dkt_links_search, the bounce-back and the nodes
!> inside the disks the submodule dkt_links_bounce; the disks themselves (`particles_t`) are
!> dkt_particles'.
module dkt_links
  use dkt_kinds, only: wp, i8
  use dkt_domain, only: domain_t
  use dkt_store, only: lattice_t
  use dkt_cells, only: cells_t
  use dkt_choices, only: BB_YU
  use dkt_particles, only: particles_t, particles_reduce_forces
  implicit none
  private
  public :: links_t, links_init, links_find, links_bounce, links_interior, &
            links_interior_after_move, links_inner_save, links_inner_write, links_refill, &
            links_reduce_forces, links_count, links_work, links_fluid_interior, links_table, &
            links_inner_table, particles_solid_field, links_row_work

  !> An interior link: node x_s of this slab inside particle k whose neighbour x_f = x_s - e_i
  !! is a lattice node outside k.
  type :: inner_link_t
    integer :: k = 0, i = 0, j = 0, d = 0 !! particle, column, local row of x_s, direction i
    real(wp) :: q = 1                     !! fluid fraction of the link x_f -> x_s
    logical :: ff = .false.               !! x_f is a fluid node
    real(wp) :: val = 0                   !! f_i(x_s, t+1), saved before E6
  end type inner_link_t

  !> The links of one slab's disks (disk k is disk k of the particles' state `ps%p`).
  type :: links_t
    private
    integer :: scheme = BB_YU           !! coupling.bounce_back
    logical :: galilean = .false.       !! E7 with (e - u_w) (Wen et al. 2014)
    logical :: fluid_interior = .false. !! coupling.interior = 'fluid'
    !> the present centres in cells of side 2 rmax, for the nodes inside disks (place_for_nodes)
    type(cells_t) :: ncells
    !> the nodes of rows 0..nyl+1 inside a disk (the present centres, place_for_nodes)
    logical, allocatable :: solid(:, :)
    !> the disks (x, y, r) and the slab's first row y0 that `solid` and `ncells` were built from:
    !! a placement of the same disks is skipped, and a new one clears only their boxes
    integer :: nplaced = -1, placed_y0 = 0
    real(wp), allocatable :: placed(:, :)
    ! boundary links of this slab, ordered by particle, row, column, direction
    integer :: nlinks = 0
    integer, allocatable :: lp(:), lx(:), ly(:), ld(:)  !! particle, column, local row, direction
    real(wp), allocatable :: lq(:)                      !! fluid fraction of the link
    logical, allocatable :: lff(:)                      !! second fluid node available
    integer, allocatable :: lrow(:)                     !! the row-sum entry of the link
    !> the links of local row j are lorder(lstart(j) .. lstart(j + 1) - 1), in their order
    integer, allocatable :: lorder(:), lstart(:)
    ! E7 per particle and row: entry e sums the links of particle rk(e) in local row rj(e);
    ! a particle's entries are rfirst(k)..rlast(k), ascending rows
    integer :: nrows = 0
    integer, allocatable :: rk(:), rj(:), rfirst(:), rlast(:)
    real(wp), allocatable :: rows(:, :)                 !! (3, entry): force x, y, torque
    !> the first link of each row-sum entry (those of entry e are rlink(e)..rlink(e + 1) - 1)
    integer, allocatable :: rlink(:)
    ! interior links (coupling.interior = 'fluid' only), ordered like the boundary links
    integer :: ninner = 0
    type(inner_link_t), allocatable :: inner(:)
    real(wp), allocatable :: rho_first(:), rho_last(:)  !! density of rows 1, nyl (columns 1..nx)
    real(wp), allocatable :: rho_below(:), rho_above(:) !! the same of halo rows 0, nyl+1
    ! the nodes inside each disk, a run of columns per row (place_for_nodes): disk k of the last
    ! placement covers columns span(1, m, k)..span(2, m, k) of local row span_j0(k) + m - 1,
    ! m = 1..span_nj(k); the *_old arrays keep the placement before it (the disks before the
    ! move, for the refill): nplaced_old disks placed_old, first row placed_y0_old
    integer, allocatable :: span(:, :, :), span_j0(:), span_nj(:)
    integer, allocatable :: span_old(:, :, :), span_j0_old(:), span_nj_old(:)
    real(wp), allocatable :: placed_old(:, :)
    integer :: nplaced_old = -1, placed_y0_old = 0
    !> what the last link search found and read, kept for the next one (search_links): the
    !! kept_n disks (-1: none) of ids kept_id, whose runs were those of placement number
    !! kept_placement (placements counts them), in a slab of first row kept_y0 and kept_nx x
    !! kept_nyl nodes; their links kept_lx, kept_ly, kept_ld, kept_lff, kept_lrow and row-sum
    !! entries kept_rj, kept_rlink, disk m's kept_rfirst..kept_rlast
    integer :: kept_n = -1, kept_y0 = 0, kept_nx = 0, kept_nyl = 0
    integer :: placements = 0, kept_placement = 0
    integer, allocatable :: kept_id(:)
    integer, allocatable :: kept_lx(:), kept_ly(:), kept_ld(:), kept_lrow(:), kept_rj(:)
    integer, allocatable :: kept_rlink(:)
    integer, allocatable :: kept_rfirst(:), kept_rlast(:)
    logical, allocatable :: kept_lff(:)
    !> the work (the `work per step` line, the cost model of docs/performance.md): link
    !! searches and the links they found, interior resets and the nodes they set
    integer(i8) :: searches = 0, links_found = 0, resets = 0, nodes_reset = 0
  end type links_t

  interface
    !> Place the present centres for is_fluid: in cells (a node lies only in disks whose centres
    !! are within rmax of it), the runs of nodes of rows 0..nyl+1 inside each disk the slab holds
    !! (disk_spans) and their mask (a slab holds every disk that reaches a row beyond it). The
    !! disks of the last placement are kept (lk%placed) with their runs: when the slab and every
    !! disk are the same (the links are found after the refill of the same step, unless the
    !! window moved) nothing is done; otherwise the runs become those of the placement before
    !! (the refill reads the disks before the move from them), and only their nodes are cleared
    !! from the mask, not the whole slab.
    module subroutine place_for_nodes(lk, ps, dom)
      type(links_t), intent(inout) :: lk
      type(particles_t), intent(in) :: ps
      type(domain_t), intent(in) :: dom
    end subroutine place_for_nodes

    !> The nodes of the disk (x, y) of radius r in the rows of its mask box (rows 0..nyl+1 of the
    !! slab): row j0 + m - 1 holds the columns sp(1, m)..sp(2, m) inside the disk, within
    !! columns 0..nx+1 (the columns beyond the sides too, where a link may end); NO_LO, NO_HI when
    !! none. nj rows (none for a centre that is not finite). Each end is the last column where
    !! the test holds next to the first where it fails, both evaluated.
    pure module subroutine disk_spans(x, y, r, dom, j0, nj, sp, gj0, gnj, gsp)
      real(wp), intent(in) :: x, y, r
      type(domain_t), intent(in) :: dom
      integer, intent(out) :: j0, nj
      integer, intent(inout) :: sp(:, :)
      integer, intent(in), optional :: gj0, gnj, gsp(:, :)
    end subroutine disk_spans

    !> Whether the placement before the present one placed disk m at (x, y) of radius r in this
    !! slab, whose runs old_spans then are (the refill's disks before the move).
    pure logical module function old_spans_of(lk, dom, m, x, y, r) result(kept)
      type(links_t), intent(in) :: lk
      type(domain_t), intent(in) :: dom
      integer, intent(in) :: m
      real(wp), intent(in) :: x, y, r
    end function old_spans_of

    !> Whether global node (i, jg) is a fluid node: in the channel and outside every particle.
    !! Within the slab and a row beyond it the mask says it (place_for_nodes); elsewhere
    !! fluid_far tests the disks near the node. Both need the present centres.
    pure logical module function is_fluid(lk, ps, dom, i, jg)
      type(links_t), intent(in) :: lk
      type(particles_t), intent(in) :: ps
      type(domain_t), intent(in) :: dom
      integer, intent(in) :: i, jg
    end function is_fluid

    !> The boundary links of this slab without their q: fluid node x_f in rows 1..nyl whose
    !! neighbour x_f + e_i lies inside a particle, ordered by particle, row, column, direction;
    !! lff says whether x_f - e_i is a fluid node. Then the row-sum entries (one per particle and
    !! row that holds links; particle k's are rfirst(k)..rlast(k), entry e's links
    !! rlink(e)..rlink(e + 1) - 1) and the links by row (row_entries).
    !!
    !! A disk's links are those of the last search (kept_*) when its runs are the same and no
    !! node within two of its runs' box (the nodes its search reads: the nodes beside its runs
    !! and one beyond, for lff) changed in the mask. The mask changes only at nodes that some disk
    !! covered then and not now or now and not then: in a row where a disk's run changed, between
    !! its old and new ends; anywhere in the runs of a disk that came or went. Those nodes are
    !! noted in blocks of BLOCK x BLOCK nodes.
    module subroutine search_links(lk, ps, dom)
      type(links_t), intent(inout) :: lk
      type(particles_t), intent(in) :: ps
      type(domain_t), intent(in) :: dom
    end subroutine search_links

    !> Find the boundary links of this slab: fluid node x_f in rows 1..nyl whose neighbour
    !! x_f + e_i lies inside a particle; q in (0, 1] is the fraction of the link in the fluid
    !! (exact intersection of the segment with the circle), computed anew for every link (the
    !! centres move). The links (search_links) are ordered by particle, row, column, direction;
    !! the interior links (coupling.interior = 'fluid') likewise.
    module subroutine links_find(lk, ps, dom)
      type(links_t), intent(inout) :: lk
      type(particles_t), intent(in) :: ps
      type(domain_t), intent(in) :: dom
    end subroutine links_find

    !> Interior side of the links (coupling.interior = 'fluid'), first half: with the halo rows
    !! complete and before any boundary link is bounced, save for each interior link (x_s, i)
    !! the population the interior node receives, half-way bounce-back from the inside,
    !!     f_i(x_s, t+1) = f_ibar*(x_s) - W,
    !! W the moving-wall term of the boundary link (x_f, i) (rho the density at x_f it uses, 1
    !! when x_f is not a fluid node). The densities of the halo rows come from their owners, so
    !! a link across a slab face uses the bits its boundary link uses. Every rank calls it.
    module subroutine links_inner_save(lk, ps, dom, f)
      type(links_t), intent(inout) :: lk
      type(particles_t), intent(in) :: ps
      type(domain_t), intent(in) :: dom
      type(lattice_t), intent(in) :: f
    end subroutine links_inner_save

    !> Interior side, second half: after every boundary link has been bounced (E6 and E7 read
    !! f_i*(x_f) and the density at x_f), write each saved value into slot i of x_f, which only
    !! x_s pulls in the sweep.
    module subroutine links_inner_write(lk, f)
      type(links_t), intent(in) :: lk
      type(lattice_t), intent(inout) :: f
    end subroutine links_inner_write

    !> E6 and E7 on the links whose fluid node lies in rows j1..j2: write the bounced population
    !! f_ibar(x_f, t+1) into the slot of the solid node that x_f pulls it from, and add the link's
    !! momentum exchange to the sums of rows j1..j2 (restarted here). f holds post-collision
    !! populations, with the ghosts complete and, when j1..j2 touches row 1 or nyl, the halo rows
    !! too. A link reads only fluid nodes (x_f, and x_f - e_i for Yu/BFL) and writes only a solid
    !! slot that no other link reads and only x_f pulls, so links of rows 2..nyl-1 neither read
    !! nor write a halo row, and the links can be taken in row groups while the halo travels.
    module subroutine links_bounce(lk, ps, dom, f, j1, j2)
      type(links_t), intent(inout) :: lk
      type(particles_t), intent(in) :: ps
      type(domain_t), intent(in) :: dom
      type(lattice_t), intent(inout) :: f
      integer, intent(in) :: j1, j2 !! rows of the fluid nodes whose links are bounced
    end subroutine links_bounce

    !> After the sweep: interior nodes get the equilibrium at the local particle velocity (they
    !! are not fluid; this keeps them finite and ready for refilling).
    module subroutine links_interior(lk, ps, dom, f)
      type(links_t), intent(inout) :: lk
      type(particles_t), intent(in) :: ps
      type(domain_t), intent(in) :: dom
      type(lattice_t), intent(inout) :: f
    end subroutine links_interior

    !> links_interior of the last step, done after its move and refill: the disks held before
    !! the move (ps%old) and their velocities then, as links_interior took them, but not the
    !! nodes the refill rewrote (inside an old disk and outside every new one, no longer in the
    !! mask). The lattice is then what links_interior before the move and the refill after
    !! it leave. No fluid node and no link reads an interior node (a fluid node pulls from a solid
    !! one only through a link, whose bounce-back overwrites the slot first; the refill and the
    !! density sums read fluid nodes only), so a step needs this only when the lattice is read
    !! whole: for output, a guard, a checkpoint (docs/performance.md).
    module subroutine links_interior_after_move(lk, ps, dom, f)
      type(links_t), intent(inout) :: lk
      type(particles_t), intent(in) :: ps
      type(domain_t), intent(in) :: dom
      type(lattice_t), intent(inout) :: f
    end subroutine links_interior_after_move

    !> Nodes inside a particle's old disk (ps%old, the disks held before the move) and outside
    !! every new one become fluid: equilibrium at the wall velocity there with the mean density of
    !! their fluid neighbours. The particles are taken in id order, as one rank would take them; a
    !! particle held before and not now, or now and not before, is beyond the reach of this slab's
    !! rows in one of the two states and so uncovers none of its nodes. The nodes inside a disk
    !! are its runs (place_for_nodes): those of the old disk are kept from the placement before
    !! the move when it placed the same disk, and found again otherwise. Nothing with interior
    !! fluid (coupling.interior = 'fluid'), where an uncovered node already holds fluid.
    module subroutine links_refill(lk, ps, dom, f)
      type(links_t), intent(inout) :: lk
      type(particles_t), intent(in) :: ps
      type(domain_t), intent(in) :: dom
      type(lattice_t), intent(inout) :: f
    end subroutine links_refill

    !> The particle index at each node of the slab (0 in the fluid), for output.
    module subroutine particles_solid_field(ps, dom, id)
      type(particles_t), intent(in) :: ps
      type(domain_t), intent(in) :: dom
      real(wp), intent(out) :: id(:, :)
    end subroutine particles_solid_field

  end interface

contains

  !> No links yet, for a slab of dom%nx columns, with the coupling's bounce-back scheme (BB_*),
  !! momentum exchange and interior nodes.
  subroutine links_init(lk, dom, scheme, galilean, fluid_interior)
    type(links_t), intent(out) :: lk
    type(domain_t), intent(in) :: dom
    integer, intent(in) :: scheme
    logical, intent(in) :: galilean, fluid_interior
    lk%scheme = scheme
    lk%galilean = galilean
    lk%fluid_interior = fluid_interior
    allocate (lk%lp(0), lk%lx(0), lk%ly(0), lk%ld(0), lk%lq(0), lk%lff(0), lk%lrow(0))
    allocate (lk%rk(0), lk%rj(0), lk%rows(3, 0))
    if (lk%fluid_interior) then
      allocate (lk%inner(0))
      allocate (lk%rho_first(dom%nx), lk%rho_last(dom%nx), lk%rho_below(dom%nx), &
                lk%rho_above(dom%nx))
      lk%rho_below = 1.0_wp
      lk%rho_above = 1.0_wp
    end if
  end subroutine links_init

  !> E7 totals of the disks this slab owns, from the row sums of the last links_bounce here and
  !! on the neighbouring slabs (particles_reduce_forces, which sets each owner's drive).
  subroutine links_reduce_forces(lk, ps, dom)
    type(links_t), intent(in) :: lk
    type(particles_t), intent(inout) :: ps
    type(domain_t), intent(in) :: dom
    call particles_reduce_forces(ps, dom, lk%rfirst, lk%rlast, lk%rj, lk%rows)
  end subroutine links_reduce_forces

  !> The boundary links of this slab.
  pure integer function links_count(lk)
    type(links_t), intent(in) :: lk
    links_count = lk%nlinks
  end function links_count

  !> The links a search found and the nodes an interior reset set, means over the searches and
  !! resets made so far (the `work per step` line).
  pure function links_work(lk) result(work)
    type(links_t), intent(in) :: lk
    real(wp) :: work(2)
    work = [real(lk%links_found, wp)/max(lk%searches, 1_i8), &
            real(lk%nodes_reset, wp)/max(lk%resets, 1_i8)]
  end function links_work

  !> The work of each row j = 1..nyl of the slab `dom`: its boundary links (those of the last
  !! search) and its nodes inside disks (the last placement's runs within columns 1..nx; a node
  !! in two disks counts twice), for the cost of a row (dkt_balance).
  pure subroutine links_row_work(lk, dom, links, nodes)
    type(links_t), intent(in) :: lk
    type(domain_t), intent(in) :: dom
    integer, intent(out) :: links(dom%nyl), nodes(dom%nyl)
    integer :: j, k, m
    links = 0
    nodes = 0
    if (allocated(lk%lstart)) then
      if (size(lk%lstart) == dom%nyl + 1) links = lk%lstart(2:) - lk%lstart(:dom%nyl)
    end if
    do k = 1, max(lk%nplaced, 0)
      if (lk%placed_y0 /= dom%y0) exit
      do m = 1, lk%span_nj(k)
        j = lk%span_j0(k) + m - 1
        if (j < 1 .or. j > dom%nyl) cycle
        nodes(j) = nodes(j) + max(0, min(lk%span(2, m, k), dom%nx) - max(lk%span(1, m, k), 1) + 1)
      end do
    end do
  end subroutine links_row_work

  !> Whether the interior nodes hold fluid (coupling.interior = 'fluid').
  pure logical function links_fluid_interior(lk)
    type(links_t), intent(in) :: lk
    links_fluid_interior = lk%fluid_interior
  end function links_fluid_interior

  !> The boundary links as a table, one column per link in their order: the disk (index into
  !! the state), column, local row, direction, and 1 when the second fluid node exists.
  pure function links_table(lk) result(t)
    type(links_t), intent(in) :: lk
    integer :: t(5, lk%nlinks), l
    do l = 1, lk%nlinks
      t(:, l) = [lk%lp(l), lk%lx(l), lk%ly(l), lk%ld(l), merge(1, 0, lk%lff(l))]
    end do
  end function links_table

  !> The interior links (coupling.interior = 'fluid') as links_table has the boundary ones.
  pure function links_inner_table(lk) result(t)
    type(links_t), intent(in) :: lk
    integer :: t(5, lk%ninner), l
    do l = 1, lk%ninner
      associate (a => lk%inner(l))
        t(:, l) = [a%k, a%i, a%j, a%d, merge(1, 0, a%ff)]
      end associate
    end do
  end function links_inner_table
end module dkt_links

!> The search for the boundary links of the disks a slab holds (docs/model.md §3): the nodes
!> each disk covers, row by row, the mask of the nodes inside a disk, and the links (without
!> their fractions q, which dkt_particle_links computes) with the row-sum entries and the order
!> by row that the bounce-back reads.
!>
!> A node (i, j) lies inside a disk (X, Y, r) when |x - X|^2 + |y - Y|^2 < r^2, with the bits of
!> dkt_link_geometry's disk_inside (inside_at). Along a row, x - X is a rounded difference that
!> never decreases with i, and the sum never decreases with |x - X|: the nodes of a row inside
!> the disk are one run of columns lo..hi, the same run the test gives node by node. The ends of
!> each run are found with that test (the runs of the last placement, or a square root, only
!> guess where to start looking), so the runs, the mask and every link found from them carry
!> the bits of the test itself.
!>
!> The links of a disk depend on its runs and on the mask near it, nothing else: a disk whose
!> runs are those of the last search, with no node of the mask changed near it, has the links it
!> had then, which are taken over instead of searched again (search_links). q is computed anew
!> for every link each step (dkt_particle_links), as the centres move.
module dkt_link_search
  use ieee_arithmetic, only: ieee_is_finite
  use dkt_kinds, only: wp
  use dkt_lattice, only: ex, ey
  use dkt_domain, only: domain_t
  use dkt_cells, only: cells_build, cells_box
  use dkt_particles, only: particles_t
  use dkt_link_geometry, only: disk_inside
  implicit none
  private
  public :: place_for_nodes, disk_spans, old_spans_of, is_fluid, search_links

  !> The ends of the run of a row without nodes inside the disk: no column lies within them,
  !! and they leave the other runs' smallest start and largest end as they are.
  integer, parameter :: NO_LO = 2**30, NO_HI = -2**30
  !> The side of the blocks of nodes in which search_links notes where the mask changed
  integer, parameter :: BLOCK = 4

contains

  !> Whether the point (px, py) lies strictly inside the disk (x, y) of radius r, with the bits
  !! of disk_inside: at once when the squared distance, however its products and sums are
  !! rounded (within a few units in the last place of each other), lies clearly on one side of
  !! r^2; by disk_inside itself otherwise.
  pure logical function inside_at(x, y, r, px, py) result(inside)
    real(wp), intent(in) :: x, y, r, px, py
    real(wp), parameter :: MARGIN = 1.0e-12_wp
    real(wp) :: d2, r2
    r2 = r*r
    d2 = (px - x)**2 + (py - y)**2
    if (d2 < r2*(1.0_wp - MARGIN)) then
      inside = .true.
    else if (d2 > r2*(1.0_wp + MARGIN)) then
      inside = .false.
    else
      inside = disk_inside(x, y, r, px, py)
    end if
  end function inside_at

  !> Place the present centres for is_fluid: in cells (a node lies only in disks whose centres
  !! are within rmax of it), the runs of nodes of rows 0..nyl+1 inside each disk the slab holds
  !! (disk_spans) and their mask (a slab holds every disk that reaches a row beyond it). The
  !! disks of the last placement are kept (ps%placed) with their runs: when the slab and every
  !! disk are the same (the links are found after the refill of the same step, unless the
  !! window moved) nothing is done; otherwise the runs become those of the placement before
  !! (the refill reads the disks before the move from them), and only their nodes are cleared
  !! from the mask, not the whole slab.
  subroutine place_for_nodes(ps, dom)
    type(particles_t), intent(inout) :: ps
    type(domain_t), intent(in) :: dom
    integer :: k, j, m, nrows
    logical :: near
    real(wp), allocatable :: tr(:, :)
    integer, allocatable :: ti(:, :, :)
    if (allocated(ps%solid)) then
      if (ubound(ps%solid, 1) /= dom%nx .or. ubound(ps%solid, 2) /= dom%nyl + 1) &
        deallocate (ps%solid)
    end if
    if (.not. allocated(ps%solid)) then
      allocate (ps%solid(1:dom%nx, 0:dom%nyl + 1))
      ps%nplaced = -1
    end if
    if (ps%nplaced == ps%n .and. ps%placed_y0 == dom%y0) then
      if (all(ps%placed(1, 1:ps%n) == ps%p%x(1:ps%n) .and. &
              ps%placed(2, 1:ps%n) == ps%p%y(1:ps%n) .and. &
              ps%placed(3, 1:ps%n) == ps%p%r(1:ps%n))) return
    end if
    if (ps%nplaced < 0 .or. ps%placed_y0 /= dom%y0) then
      ps%solid = .false.
    else
      do k = 1, ps%nplaced
        do m = 1, ps%span_nj(k)
          j = ps%span_j0(k) + m - 1
          ps%solid(max(ps%span(1, m, k), 1):min(ps%span(2, m, k), dom%nx), j) = .false.
        end do
      end do
    end if
    ! the present runs become the old ones, and the old arrays take the new runs
    call move_alloc(ps%placed, tr)
    call move_alloc(ps%placed_old, ps%placed)
    call move_alloc(tr, ps%placed_old)
    call move_alloc(ps%span, ti)
    call move_alloc(ps%span_old, ps%span)
    call move_alloc(ti, ps%span_old)
    call swap(ps%span_j0, ps%span_j0_old)
    call swap(ps%span_nj, ps%span_nj_old)
    ps%nplaced_old = ps%nplaced
    ps%placed_y0_old = ps%placed_y0
    call cells_build(ps%ncells, ps%p%x(1:ps%n), ps%p%y(1:ps%n), 2.0_wp*ps%rmax)
    ! a disk of radius r covers at most 2 r + 3 rows of mask_box
    nrows = 4
    if (ps%n > 0) nrows = max(nrows, int(min(2.0_wp*maxval(ps%p%r(1:ps%n)), 1.0e6_wp)) + 4)
    if (allocated(ps%placed)) then
      if (size(ps%placed, 2) < ps%n) deallocate (ps%placed)
    end if
    if (.not. allocated(ps%placed)) allocate (ps%placed(3, max(ps%n, 2*ps%nplaced, 16)))
    if (allocated(ps%span)) then
      if (size(ps%span, 2) < nrows .or. size(ps%span, 3) < ps%n) &
        deallocate (ps%span, ps%span_j0, ps%span_nj)
    end if
    if (.not. allocated(ps%span)) then
      m = size(ps%placed, 2)
      allocate (ps%span(2, nrows, m), ps%span_j0(m), ps%span_nj(m))
    end if
    do k = 1, ps%n
      ps%placed(:, k) = [ps%p%x(k), ps%p%y(k), ps%p%r(k)]
      ! (the runs of the placement before guess the ends when they are of a disk at nearly the
      ! same place)
      near = .false.
      if (k <= ps%nplaced_old .and. ps%placed_y0_old == dom%y0) &
        near = abs(ps%placed_old(1, k) - ps%p%x(k)) + abs(ps%placed_old(2, k) - ps%p%y(k)) < &
               1.0_wp .and. ps%placed_old(3, k) == ps%p%r(k)
      if (near) then
        call disk_spans(ps%p%x(k), ps%p%y(k), ps%p%r(k), dom, ps%span_j0(k), ps%span_nj(k), &
                        ps%span(:, :, k), ps%span_j0_old(k), ps%span_nj_old(k), &
                        ps%span_old(:, :, k))
      else
        call disk_spans(ps%p%x(k), ps%p%y(k), ps%p%r(k), dom, ps%span_j0(k), ps%span_nj(k), &
                        ps%span(:, :, k))
      end if
      do m = 1, ps%span_nj(k)
        j = ps%span_j0(k) + m - 1
        ps%solid(max(ps%span(1, m, k), 1):min(ps%span(2, m, k), dom%nx), j) = .true.
      end do
    end do
    ps%nplaced = ps%n
    ps%placed_y0 = dom%y0
    ps%placements = ps%placements + 1
  end subroutine place_for_nodes

  !> The nodes i1..i2, j1..j2 of the mask (rows 0..nyl+1) that a disk at (x, y) of radius r can
  !! cover; none (i1 > i2) for a centre that is not finite (the box is clipped before it becomes
  !! an integer).
  pure subroutine mask_box(x, y, r, dom, i1, i2, j1, j2)
    real(wp), intent(in) :: x, y, r
    type(domain_t), intent(in) :: dom
    integer, intent(out) :: i1, i2, j1, j2
    if (.not. (ieee_is_finite(x) .and. ieee_is_finite(y))) then
      i1 = 1; i2 = 0; j1 = 0; j2 = -1
      return
    end if
    i1 = max(1, int(max(min(x - r, real(dom%nx + 1, wp)), 0.0_wp)))
    i2 = min(dom%nx, int(max(min(x + r, real(dom%nx, wp)), 0.0_wp)) + 1)
    j1 = max(0, int(max(min(y - r - dom%y0, real(dom%nyl + 2, wp)), -1.0_wp) + 1.0_wp) - 1)
    j2 = min(dom%nyl + 1, int(max(min(y + r - dom%y0, real(dom%nyl + 1, wp)), -1.0_wp) + 1.0_wp))
  end subroutine mask_box

  !> The nodes of the disk (x, y) of radius r in the rows of its mask box (rows 0..nyl+1 of the
  !! slab): row j0 + m - 1 holds the columns sp(1, m)..sp(2, m) inside the disk, within
  !! columns 0..nx+1 (the columns beyond the sides too, where a link may end); NO_LO, NO_HI when
  !! none. nj rows (none for a centre that is not finite). Each end is the last column where
  !! the test holds next to the first where it fails, both evaluated.
  pure subroutine disk_spans(x, y, r, dom, j0, nj, sp, gj0, gnj, gsp)
    real(wp), intent(in) :: x, y, r
    type(domain_t), intent(in) :: dom
    integer, intent(out) :: j0, nj
    integer, intent(inout) :: sp(:, :)
    !> runs to start from (of the same disk a little earlier): rows gj0.. (gnj rows)
    integer, intent(in), optional :: gj0, gnj, gsp(:, :)
    integer :: i1, i2, j2, m, ia, s, lo, hi, last
    real(wp) :: py, dy, h
    call mask_box(x, y, r, dom, i1, i2, j0, j2)
    nj = max(j2 - j0 + 1, 0)
    if (nj == 0) return
    last = dom%nx + 1
    ! the columns whose x - X changes sign: the node nearest the centre in any row is one of
    ! ia - 1, ia, ia + 1 (x + 1/2 is rounded before the floor)
    ia = floor(max(min(x + 0.5_wp, real(last + 1, wp)), -1.0_wp))
    do m = 1, nj
      py = dom%y0 + j0 + m - 1 - 0.5_wp
      sp(1, m) = NO_LO
      sp(2, m) = NO_HI
      ! s, a node of the run: the first of the earlier run when it is still inside, with that
      ! run's ends as the guesses; else the node nearest the centre, with the half chord
      ! sqrt(r^2 - dy^2) guessing the ends
      s = -1
      if (present(gsp)) then
        if (j0 + m - 1 >= gj0 .and. j0 + m - 1 < gj0 + gnj) then
          lo = gsp(1, j0 + m - gj0)
          hi = gsp(2, j0 + m - gj0)
          if (lo <= hi) then
            if (inside_at(x, y, r, lo - 0.5_wp, py)) s = lo
          end if
        end if
      end if
      if (s < 0) then
        if (inside_at(x, y, r, clip(ia) - 0.5_wp, py)) then
          s = clip(ia)
        else if (inside_at(x, y, r, clip(ia + 1) - 0.5_wp, py)) then
          s = clip(ia + 1)
        else if (inside_at(x, y, r, clip(ia - 1) - 0.5_wp, py)) then
          s = clip(ia - 1)
        end if
        if (s < 0) cycle
        dy = py - y
        h = sqrt(max(r*r - dy*dy, 0.0_wp))
        lo = clip(floor(max(min(x - h + 0.5_wp, real(last + 1, wp)), -1.0_wp)) + 1)
        hi = clip(floor(max(min(x + h + 0.5_wp, real(last + 1, wp)), -1.0_wp)))
      end if
      ! each end walks from its guess to where the test changes
      lo = min(lo, s)
      if (lo == s .or. inside_at(x, y, r, lo - 0.5_wp, py)) then
        do while (lo > 0)
          if (.not. inside_at(x, y, r, lo - 1.5_wp, py)) exit
          lo = lo - 1
        end do
      else
        do while (.not. inside_at(x, y, r, lo - 0.5_wp, py))
          lo = lo + 1
        end do
      end if
      hi = max(hi, s)
      if (hi == s .or. inside_at(x, y, r, hi - 0.5_wp, py)) then
        do while (hi < last)
          if (.not. inside_at(x, y, r, hi + 0.5_wp, py)) exit
          hi = hi + 1
        end do
      else
        do while (.not. inside_at(x, y, r, hi - 0.5_wp, py))
          hi = hi - 1
        end do
      end if
      sp(1, m) = lo
      sp(2, m) = hi
    end do
  contains
    !> column c within 0..nx+1
    pure integer function clip(c)
      integer, intent(in) :: c
      clip = min(max(c, 0), last)
    end function clip
  end subroutine disk_spans

  !> The columns lo..hi of local row j inside disk k of the present placement (NO_LO, NO_HI
  !! for none, or a row beyond the disk's).
  pure subroutine span_of(ps, k, j, lo, hi)
    type(particles_t), intent(in) :: ps
    integer, intent(in) :: k, j
    integer, intent(out) :: lo, hi
    integer :: m
    m = j - ps%span_j0(k) + 1
    if (m >= 1 .and. m <= ps%span_nj(k)) then
      lo = ps%span(1, m, k)
      hi = ps%span(2, m, k)
    else
      lo = NO_LO
      hi = NO_HI
    end if
  end subroutine span_of

  !> Whether the placement before the present one placed disk m at (x, y) of radius r in this
  !! slab, whose runs old_spans then are (the refill's disks before the move).
  pure logical function old_spans_of(ps, dom, m, x, y, r) result(kept)
    type(particles_t), intent(in) :: ps
    type(domain_t), intent(in) :: dom
    integer, intent(in) :: m
    real(wp), intent(in) :: x, y, r
    kept = m <= ps%nplaced_old .and. ps%placed_y0_old == dom%y0
    if (kept) kept = ps%placed_old(1, m) == x .and. ps%placed_old(2, m) == y .and. &
                     ps%placed_old(3, m) == r
  end function old_spans_of

  !> Whether global node (i, jg) is a fluid node: in the channel and outside every particle.
  !! Within the slab and a row beyond it the mask says it (place_for_nodes); elsewhere
  !! fluid_far tests the disks near the node. Both need the present centres.
  pure logical function is_fluid(ps, dom, i, jg)
    type(particles_t), intent(in) :: ps
    type(domain_t), intent(in) :: dom
    integer, intent(in) :: i, jg
    is_fluid = i >= 1 .and. i <= dom%nx .and. (dom%periodic_y .or. (jg >= 1 .and. jg <= dom%ny))
    if (.not. is_fluid) return
    if (jg - dom%y0 >= 0 .and. jg - dom%y0 <= dom%nyl + 1) then
      is_fluid = mask_fluid(ps, dom, i, jg - dom%y0)
    else
      is_fluid = fluid_far(ps, i, jg)
    end if
  end function is_fluid

  !> Whether the channel node (i, jg), beyond the mask's rows, lies outside every particle the
  !! slab holds: only the disks of the cells within rmax of the node are tested.
  pure logical function fluid_far(ps, i, jg) result(fluid)
    type(particles_t), intent(in) :: ps
    integer, intent(in) :: i, jg
    integer :: k, l, i1, i2, j1, j2, jc
    real(wp) :: px, py
    px = i - 0.5_wp
    py = jg - 0.5_wp
    call cells_box(ps%ncells, px, py, ps%rmax, i1, i2, j1, j2)
    if (i1 == 0) then
      fluid = .not. any([(inside_at(ps%p%x(k), ps%p%y(k), ps%p%r(k), px, py), k=1, ps%n)])
      return
    end if
    fluid = .true.
    associate (c => ps%ncells)
      ! the cells i1..i2 of a row of cells hold one run of c%items
      do jc = j1, j2
        do l = c%start(i1 + c%nx*(jc - 1)), c%start(i2 + 1 + c%nx*(jc - 1)) - 1
          k = c%items(l)
          if (inside_at(ps%p%x(k), ps%p%y(k), ps%p%r(k), px, py)) fluid = .false.
        end do
      end do
      do l = 1, size(c%stray)
        k = c%stray(l)
        if (inside_at(ps%p%x(k), ps%p%y(k), ps%p%r(k), px, py)) fluid = .false.
      end do
    end associate
  end function fluid_far

  !> is_fluid for the node (i, j) of the slab's rows 0..nyl+1, which the mask covers.
  pure logical function mask_fluid(ps, dom, i, j) result(fluid)
    type(particles_t), intent(in) :: ps
    type(domain_t), intent(in) :: dom
    integer, intent(in) :: i, j
    fluid = i >= 1 .and. i <= dom%nx .and. &
            (dom%periodic_y .or. (dom%y0 + j >= 1 .and. dom%y0 + j <= dom%ny))
    if (fluid) fluid = .not. ps%solid(i, j)
  end function mask_fluid

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
  subroutine search_links(ps, dom)
    type(particles_t), intent(inout) :: ps
    type(domain_t), intent(in) :: dom
    integer :: k, m, n, ne, n0, i1, i2, j1, j2, since
    integer :: room, room_e !! places in the arrays of the links, of the entries
    integer, allocatable :: was(:) !! the disk of the last search that disk k is, or 0
    logical, allocatable :: dirty(:, :), same(:), tl(:)
    logical :: kept
    call place_for_nodes(ps, dom)
    ! the runs the last search read: the present ones when no disk was placed since, those of
    ! the placement before (the refill's, after the move) when one was; else every disk is
    ! searched
    since = ps%placements - ps%kept_placement
    kept = ps%kept_n >= 0 .and. ps%kept_y0 == dom%y0 .and. ps%kept_nx == dom%nx .and. &
           ps%kept_nyl == dom%nyl .and. since <= 1
    ! the links of the last search become the kept ones, their arrays take the new links
    call swap(ps%lx, ps%kept_lx)
    call swap(ps%ly, ps%kept_ly)
    call swap(ps%ld, ps%kept_ld)
    call swap(ps%lrow, ps%kept_lrow)
    call swap(ps%rj, ps%kept_rj)
    call swap(ps%rlink, ps%kept_rlink)
    call swap(ps%rfirst, ps%kept_rfirst)
    call swap(ps%rlast, ps%kept_rlast)
    call move_alloc(ps%lff, tl)
    call move_alloc(ps%kept_lff, ps%lff)
    call move_alloc(tl, ps%kept_lff)
    ! the blocks of nodes where the mask may have changed, and the disks whose runs did not
    allocate (was(ps%n), same(ps%n), dirty(0:(dom%nx + 3 + BLOCK)/BLOCK, &
                                           0:(dom%nyl + 3 + BLOCK)/BLOCK))
    dirty = .false.
    was = 0
    same = .false.
    if (kept) call kept_disks(ps, dom, since, was, same, dirty)
    call fit_entries(ps, max(ps%n, 1), 0)
    room = 0
    room_e = 0
    ps%rfirst(1:ps%n) = 1
    ps%rlast(1:ps%n) = 0
    n = 0
    ne = 0
    do k = 1, ps%n
      ! room for every link of k, and the eight written for each node: at most 8 from each node
      ! beside its runs, which span no more than 2 r + 4 columns of each of its rows and the
      ! two beyond them; an entry of the row sums for each of those rows
      m = n + 8*(ps%span_nj(k) + 2)*(int(min(2.0_wp*ps%p%r(k), 1.0e6_wp)) + 6)
      if (m > room) then
        call fit_links(ps, m, n)
        room = min(size(ps%lp), size(ps%lx), size(ps%ly), size(ps%ld), size(ps%lrow), &
                   size(ps%lq), size(ps%lff))
      end if
      if (ne + ps%span_nj(k) + 3 > room_e) then
        call fit_entries(ps, ne + ps%span_nj(k) + 3, ne)
        room_e = min(size(ps%rk), size(ps%rj), size(ps%rlink) - 1, size(ps%rows, 2))
      end if
      if (same(k)) then
        call runs_box(ps%span(:, :, k), ps%span_j0(k), ps%span_nj(k), i1, i2, j1, j2)
        same(k) = .not. any(dirty(block_x(dom, i1 - 2):block_x(dom, i2 + 2), &
                                  block_y(dom, j1 - 2):block_y(dom, j2 + 2)))
      end if
      n0 = n
      if (same(k)) then
        call take_kept(ps, k, was(k), n, ne)
      else
        call disk_links(ps, dom, k, n, ne)
      end if
      ps%lp(n0 + 1:n) = k
    end do
    ps%nlinks = n
    ps%nrows = ne
    ps%rlink(ne + 1) = n + 1
    ps%searches = ps%searches + 1
    ps%links_found = ps%links_found + n
    call row_entries(ps, dom%nyl)
    call keep_runs(ps, dom)
  end subroutine search_links

  !> The disks of the last search that the present ones are (was, by id), those whose runs are
  !! the same (same), and the blocks of nodes where the mask changed since (dirty): see
  !! search_links. since: the placements since the last search, 0 or 1.
  subroutine kept_disks(ps, dom, since, was, same, dirty)
    type(particles_t), intent(in) :: ps
    type(domain_t), intent(in) :: dom
    integer, intent(in) :: since
    integer, intent(out) :: was(:)
    logical, intent(out) :: same(:)
    logical, intent(inout) :: dirty(0:, 0:)
    integer :: k, m
    was = 0
    same = .false.
    if (since == 0) then
      ! the same placement: every disk has the runs it had, the mask is the same
      do k = 1, min(ps%n, ps%kept_n)
        was(k) = k
      end do
      same = was > 0
    else
      m = 1
      do k = 1, ps%n
        do while (m <= ps%kept_n)
          if (ps%kept_id(m) >= ps%p%id(k)) exit
          call note(ps%span_old(:, :, m), ps%span_j0_old(m), ps%span_nj_old(m))
          m = m + 1
        end do
        if (m <= ps%kept_n) then
          if (ps%kept_id(m) == ps%p%id(k)) then
            was(k) = m
            same(k) = ps%span_j0_old(m) == ps%span_j0(k) .and. &
                      ps%span_nj_old(m) == ps%span_nj(k)
            if (same(k)) same(k) = all(ps%span_old(:, 1:ps%span_nj(k), m) == &
                                       ps%span(:, 1:ps%span_nj(k), k))
            if (.not. same(k)) call note_change(m, k)
            m = m + 1
          end if
        end if
        if (was(k) == 0) call note(ps%span(:, :, k), ps%span_j0(k), ps%span_nj(k))
      end do
      do m = m, ps%kept_n
        call note(ps%span_old(:, :, m), ps%span_j0_old(m), ps%span_nj_old(m))
      end do
    end if
  contains
    !> note the blocks of the box of the runs sp of rows j0.. (nj rows) as changed
    subroutine note(sp, j0, nj)
      integer, intent(in) :: sp(:, :), j0, nj
      integer :: i1, i2, j1, j2
      call runs_box(sp, j0, nj, i1, i2, j1, j2)
      if (i1 > i2) return
      dirty(block_x(dom, i1):block_x(dom, i2), block_y(dom, j1):block_y(dom, j2)) = .true.
    end subroutine note
    !> note the blocks of the nodes that disk m of the last search covered and disk k does not,
    !! or the other way round, as changed
    subroutine note_change(m, k)
      integer, intent(in) :: m, k
      integer :: j, ol, oh, nl, nh
      do j = min(ps%span_j0_old(m), ps%span_j0(k)), &
        max(ps%span_j0_old(m) + ps%span_nj_old(m), ps%span_j0(k) + ps%span_nj(k)) - 1
        ol = NO_LO
        oh = NO_HI
        if (j >= ps%span_j0_old(m) .and. j < ps%span_j0_old(m) + ps%span_nj_old(m)) then
          ol = ps%span_old(1, j - ps%span_j0_old(m) + 1, m)
          oh = ps%span_old(2, j - ps%span_j0_old(m) + 1, m)
        end if
        call span_of(ps, k, j, nl, nh)
        if (ol > oh .or. nl > nh .or. oh < nl .or. nh < ol) then
          call mark(ol, oh, j)
          call mark(nl, nh, j)
        else
          call mark(min(ol, nl), max(ol, nl) - 1, j)
          call mark(min(oh, nh) + 1, max(oh, nh), j)
        end if
      end do
    end subroutine note_change
    !> note the blocks of columns i1..i2 of row j as changed
    subroutine mark(i1, i2, j)
      integer, intent(in) :: i1, i2, j
      if (i1 <= i2) dirty(block_x(dom, i1):block_x(dom, i2), block_y(dom, j)) = .true.
    end subroutine mark
  end subroutine kept_disks

  !> The block of column i, within -2..nx+3 (search_links).
  pure integer function block_x(dom, i)
    type(domain_t), intent(in) :: dom
    integer, intent(in) :: i
    block_x = (min(max(i, -2), dom%nx + 3) + BLOCK)/BLOCK
  end function block_x
  !> The block of local row j, within -2..nyl+3.
  pure integer function block_y(dom, j)
    type(domain_t), intent(in) :: dom
    integer, intent(in) :: j
    block_y = (min(max(j, -2), dom%nyl + 3) + BLOCK)/BLOCK
  end function block_y

  !> The box i1..i2, j1..j2 of the runs sp of rows j0..j0+nj-1 (i1 > i2 when they hold no node).
  pure subroutine runs_box(sp, j0, nj, i1, i2, j1, j2)
    integer, intent(in) :: sp(:, :), j0, nj
    integer, intent(out) :: i1, i2, j1, j2
    integer :: m
    i1 = NO_LO
    i2 = NO_HI
    j1 = j0
    j2 = j0 + nj - 1
    do m = 1, nj
      i1 = min(i1, sp(1, m))
      i2 = max(i2, sp(2, m))
    end do
  end subroutine runs_box

  !> Swap the contents of two integer arrays.
  subroutine swap(a, b)
    integer, allocatable, intent(inout) :: a(:), b(:)
    integer, allocatable :: t(:)
    call move_alloc(a, t)
    call move_alloc(b, a)
    call move_alloc(t, b)
  end subroutine swap

  !> Room for m links in the arrays of the links, the first keep kept (twice as long as before
  !! when they fill, so that they keep their size from step to step).
  subroutine fit_links(ps, m, keep)
    type(particles_t), intent(inout) :: ps
    integer, intent(in) :: m, keep
    integer :: c
    logical, allocatable :: tl(:)
    c = max(m, 16)
    call fit_int(ps%lp, c, keep)
    call fit_int(ps%lx, c, keep)
    call fit_int(ps%ly, c, keep)
    call fit_int(ps%ld, c, keep)
    call fit_int(ps%lrow, c, keep)
    if (.not. allocated(ps%lq)) allocate (ps%lq(0))
    if (size(ps%lq) < c) then
      ! (q is computed after the search: nothing to keep)
      deallocate (ps%lq)
      allocate (ps%lq(max(c, 2*size(ps%lp))))
    end if
    if (.not. allocated(ps%lff)) allocate (ps%lff(0))
    if (size(ps%lff) < c) then
      allocate (tl(max(c, 2*size(ps%lff))))
      tl(1:keep) = ps%lff(1:keep)
      call move_alloc(tl, ps%lff)
    end if
  end subroutine fit_links

  !> Room for m row-sum entries and the particles' first and last entries, the first keep
  !! entries kept.
  subroutine fit_entries(ps, m, keep)
    type(particles_t), intent(inout) :: ps
    integer, intent(in) :: m, keep
    real(wp), allocatable :: tr(:, :)
    call fit_int(ps%rk, m, keep)
    call fit_int(ps%rj, m, keep)
    call fit_int(ps%rlink, m + 1, keep)
    if (size(ps%rows, 2) < size(ps%rk)) then
      allocate (tr(3, size(ps%rk)))
      call move_alloc(tr, ps%rows)
    end if
    call fit_int(ps%rfirst, ps%n, ps%n)
    call fit_int(ps%rlast, ps%n, ps%n)
  end subroutine fit_entries

  !> At least m places in a, twice as many as before when it grows, the first keep kept.
  subroutine fit_int(a, m, keep)
    integer, allocatable, intent(inout) :: a(:)
    integer, intent(in) :: m, keep
    integer, allocatable :: t(:)
    if (.not. allocated(a)) allocate (a(0))
    if (size(a) >= m) return
    allocate (t(max(m, 2*size(a), 16)))
    t(1:min(keep, size(a))) = a(1:min(keep, size(a)))
    call move_alloc(t, a)
  end subroutine fit_int

  !> Append the links of disk k that the last search found for it as disk m, and their entries.
  subroutine take_kept(ps, k, m, n, ne)
    type(particles_t), intent(inout) :: ps
    integer, intent(in) :: k, m
    integer, intent(inout) :: n, ne
    integer :: e1, e2, f1, f2, c
    e1 = ps%kept_rfirst(m)
    e2 = ps%kept_rlast(m)
    if (e1 > e2) return
    f1 = ps%kept_rlink(e1)
    f2 = ps%kept_rlink(e2 + 1) - 1
    c = f2 - f1 + 1
    call copy_links(c, ne + 1 - e1, ps%kept_lx(f1:f2), ps%kept_ly(f1:f2), ps%kept_ld(f1:f2), &
                    ps%kept_lff(f1:f2), ps%kept_lrow(f1:f2), ps%lx(n + 1:n + c), &
                    ps%ly(n + 1:n + c), ps%ld(n + 1:n + c), ps%lff(n + 1:n + c), &
                    ps%lrow(n + 1:n + c))
    ps%rk(ne + 1:ne + e2 - e1 + 1) = k
    ps%rj(ne + 1:ne + e2 - e1 + 1) = ps%kept_rj(e1:e2)
    ps%rlink(ne + 1:ne + e2 - e1 + 1) = ps%kept_rlink(e1:e2) + (n + 1 - f1)
    ps%rfirst(k) = ne + 1
    ps%rlast(k) = ne + e2 - e1 + 1
    n = n + c
    ne = ne + e2 - e1 + 1
  end subroutine take_kept

  !> Copy c links (their entries moved by de).
  pure subroutine copy_links(c, de, ax, ay, ad, af, ar, bx, by, bd, bf, br)
    integer, intent(in) :: c, de
    integer, intent(in) :: ax(c), ay(c), ad(c), ar(c)
    logical, intent(in) :: af(c)
    integer, intent(out) :: bx(c), by(c), bd(c), br(c)
    logical, intent(out) :: bf(c)
    integer :: l
    do l = 1, c
      bx(l) = ax(l)
      by(l) = ay(l)
      bd(l) = ad(l)
      bf(l) = af(l)
      br(l) = ar(l) + de
    end do
  end subroutine copy_links

  !> Note what the links were found from for the next search: the disks (by id), the placement
  !! of their runs and the slab.
  subroutine keep_runs(ps, dom)
    type(particles_t), intent(inout) :: ps
    type(domain_t), intent(in) :: dom
    call fit_int(ps%kept_id, ps%n, 0)
    ps%kept_id(1:ps%n) = ps%p%id(1:ps%n)
    ps%kept_n = ps%n
    ps%kept_placement = ps%placements
    ps%kept_y0 = dom%y0
    ps%kept_nx = dom%nx
    ps%kept_nyl = dom%nyl
  end subroutine keep_runs

  !> Append the boundary links of disk k after the n found (the arrays hold room for them and
  !! eight more), and an entry of the row sums for each row that has some after the ne there
  !! are; k's entries are rfirst(k)..rlast(k).
  !!
  !! A link of k starts next to a node inside k, so only the nodes beside k's runs are looked
  !! at: in row j the columns from one before the first to one after the last run of rows
  !! j - 1..j + 1, without k's own run (nodes inside k are not fluid). Whether x_f + e_i lies
  !! inside k is whether its column is in the run of its row, which is the test itself (and the
  !! mask, built from the same runs, holds it). The links come out in the order of a scan of
  !! the whole box: row, column, direction.
  subroutine disk_links(ps, dom, k, n, ne)
    type(particles_t), intent(inout) :: ps
    type(domain_t), intent(in) :: dom
    integer, intent(in) :: k
    integer, intent(inout) :: n, ne
    integer :: j, l, m, n0, nr, lo(-1:1), hi(-1:1), a(8), b(8)
    n0 = n
    associate (lx => ps%lx, ly => ps%ly, ld => ps%ld, j0 => ps%span_j0(k), &
               nj => ps%span_nj(k))
      do j = max(1, j0 - 1), min(dom%nyl, j0 + nj)
        do m = -1, 1
          lo(m) = NO_LO
          hi(m) = NO_HI
          if (j + m >= j0 .and. j + m < j0 + nj) then
            lo(m) = ps%span(1, j + m - j0 + 1, k)
            hi(m) = ps%span(2, j + m - j0 + 1, k)
          end if
        end do
        ! the neighbour x_f + e_d of node i lies inside k when a(d) <= i <= b(d)
        a = lo(ey(1:8)) - ex(1:8)
        b = hi(ey(1:8)) - ex(1:8)
        nr = n
        ! (a node outside the channel is not fluid)
        if (dom%periodic_y .or. (dom%y0 + j >= 1 .and. dom%y0 + j <= dom%ny)) &
          call row_links(max(1, minval(lo) - 1), min(dom%nx, maxval(hi) + 1), lo(0), hi(0), &
                         a, b, ps%solid(:, j), lx, ld, n)
        if (n > nr) then
          ne = ne + 1
          if (n0 == nr) ps%rfirst(k) = ne
          ps%rlast(k) = ne
          ps%rk(ne) = k
          ps%rj(ne) = j
          ps%rlink(ne) = nr + 1
          ly(nr + 1:n) = j
          ps%lrow(nr + 1:n) = ne
        end if
      end do
      do l = n0 + 1, n
        ps%lff(l) = mask_fluid(ps, dom, lx(l) - ex(ld(l)), ly(l) - ey(ld(l)))
      end do
    end associate
  end subroutine disk_links

  !> The links of the nodes i1..i2 of a row but lo..hi (inside the disk) after the n found: node
  !! i has one along d when it is fluid (not solid(i)) and a(d) <= i <= b(d). Each direction is
  !! written at the next place, which only a link there keeps (lx and ld hold eight places
  !! more than the links).
  pure subroutine row_links(i1, i2, lo, hi, a, b, solid, lx, ld, n)
    integer, intent(in) :: i1, i2, lo, hi, a(8), b(8)
    logical, intent(in) :: solid(*)
    integer, intent(inout) :: lx(*), ld(*)
    integer, intent(inout) :: n
    integer :: i, d
    i = i1
    do while (i <= i2)
      if (i >= lo .and. i <= hi) then
        i = hi + 1
        cycle
      end if
      if (.not. solid(i)) then
        do d = 1, 8
          ld(n + 1) = d
          lx(n + 1) = i
          n = n + merge(1, 0, i >= a(d) .and. i <= b(d))
        end do
      end if
      i = i + 1
    end do
  end subroutine row_links

  !> The row sums of E7 restarted, and the links by row: lorder(lstart(j)..lstart(j + 1) - 1)
  !! are the links of row j in their order.
  subroutine row_entries(ps, nyl)
    type(particles_t), intent(inout) :: ps
    integer, intent(in) :: nyl !! rows of the slab
    integer :: l, k, n, m
    ps%rows(:, 1:ps%nrows) = 0.0_wp
    if (.not. allocated(ps%lstart)) allocate (ps%lstart(0))
    if (size(ps%lstart) /= nyl + 1) then
      deallocate (ps%lstart)
      allocate (ps%lstart(nyl + 1))
    end if
    if (.not. allocated(ps%lorder)) allocate (ps%lorder(0))
    if (size(ps%lorder) < ps%nlinks) then
      deallocate (ps%lorder)
      allocate (ps%lorder(max(ps%nlinks, 2*size(ps%lp))))
    end if
    ! a stable counting sort, taken entry by entry: the links of an entry are a run of one row,
    ! so each entry adds its run to its row's count and then copies it in one piece
    associate (lstart => ps%lstart, lorder => ps%lorder, rj => ps%rj, first => ps%rlink)
      lstart = 0
      do n = 1, ps%nrows
        lstart(rj(n)) = lstart(rj(n)) + (first(n + 1) - first(n))
      end do
      m = 1
      do k = 1, nyl + 1
        n = lstart(k)
        lstart(k) = m
        m = m + n
      end do
      do n = 1, ps%nrows
        k = rj(n)
        m = lstart(k) - first(n)
        do l = first(n), first(n + 1) - 1
          lorder(m + l) = l
        end do
        lstart(k) = lstart(k) + (first(n + 1) - first(n))
      end do
      ! each start now points at the next row's first link: shift back by one row
      lstart(2:) = lstart(1:nyl)
      lstart(1) = 1
    end associate
  end subroutine row_entries
end module dkt_link_search

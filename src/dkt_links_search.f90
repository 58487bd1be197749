!> The search for the boundary links of the disks a slab holds (docs/model.md §3): the nodes
!> each disk covers, row by row, the mask of the nodes inside a disk, and the links (without
!> their fractions q, which dkt_links_bounce computes) with the row-sum entries and the order
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
!> for every link each step (dkt_links_bounce), as the centres move.
submodule(dkt_links) dkt_links_search
  use ieee_arithmetic, only: ieee_is_finite
  use dkt_kinds, only: wp
  use dkt_lattice, only: ex, ey
  use dkt_domain, only: domain_t
  use dkt_cells, only: cells_build, cells_box
  use dkt_link_geometry, only: disk_inside
  implicit none

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

  module subroutine place_for_nodes(lk, ps, dom)
    type(links_t), intent(inout) :: lk
    type(particles_t), intent(in) :: ps
    type(domain_t), intent(in) :: dom
    integer :: k, j, m, nrows
    logical :: near
    real(wp), allocatable :: tr(:, :)
    integer, allocatable :: ti(:, :, :)
    if (allocated(lk%solid)) then
      if (ubound(lk%solid, 1) /= dom%nx .or. ubound(lk%solid, 2) /= dom%nyl + 1) &
        deallocate (lk%solid)
    end if
    if (.not. allocated(lk%solid)) then
      allocate (lk%solid(1:dom%nx, 0:dom%nyl + 1))
      lk%nplaced = -1
    end if
    if (lk%nplaced == ps%n .and. lk%placed_y0 == dom%y0) then
      if (all(lk%placed(1, 1:ps%n) == ps%p%x(1:ps%n) .and. &
              lk%placed(2, 1:ps%n) == ps%p%y(1:ps%n) .and. &
              lk%placed(3, 1:ps%n) == ps%p%r(1:ps%n))) return
    end if
    if (lk%nplaced < 0 .or. lk%placed_y0 /= dom%y0) then
      lk%solid = .false.
    else
      do k = 1, lk%nplaced
        do m = 1, lk%span_nj(k)
          j = lk%span_j0(k) + m - 1
          lk%solid(max(lk%span(1, m, k), 1):min(lk%span(2, m, k), dom%nx), j) = .false.
        end do
      end do
    end if
    ! the present runs become the old ones, and the old arrays take the new runs
    call move_alloc(lk%placed, tr)
    call move_alloc(lk%placed_old, lk%placed)
    call move_alloc(tr, lk%placed_old)
    call move_alloc(lk%span, ti)
    call move_alloc(lk%span_old, lk%span)
    call move_alloc(ti, lk%span_old)
    call swap(lk%span_j0, lk%span_j0_old)
    call swap(lk%span_nj, lk%span_nj_old)
    lk%nplaced_old = lk%nplaced
    lk%placed_y0_old = lk%placed_y0
    call cells_build(lk%ncells, ps%p%x(1:ps%n), ps%p%y(1:ps%n), 2.0_wp*ps%rmax)
    ! a disk of radius r covers at most 2 r + 3 rows of mask_box
    nrows = 4
    if (ps%n > 0) nrows = max(nrows, int(min(2.0_wp*maxval(ps%p%r(1:ps%n)), 1.0e6_wp)) + 4)
    if (allocated(lk%placed)) then
      if (size(lk%placed, 2) < ps%n) deallocate (lk%placed)
    end if
    if (.not. allocated(lk%placed)) allocate (lk%placed(3, max(ps%n, 2*lk%nplaced, 16)))
    if (allocated(lk%span)) then
      if (size(lk%span, 2) < nrows .or. size(lk%span, 3) < ps%n) &
        deallocate (lk%span, lk%span_j0, lk%span_nj)
    end if
    if (.not. allocated(lk%span)) then
      m = size(lk%placed, 2)
      allocate (lk%span(2, nrows, m), lk%span_j0(m), lk%span_nj(m))
    end if
    do k = 1, ps%n
      lk%placed(:, k) = [ps%p%x(k), ps%p%y(k), ps%p%r(k)]
      ! (the runs of the placement before guess the ends when they are of a disk at nearly the
      ! same place)
      near = .false.
      if (k <= lk%nplaced_old .and. lk%placed_y0_old == dom%y0) &
        near = abs(lk%placed_old(1, k) - ps%p%x(k)) + abs(lk%placed_old(2, k) - ps%p%y(k)) < &
               1.0_wp .and. lk%placed_old(3, k) == ps%p%r(k)
      if (near) then
        call disk_spans(ps%p%x(k), ps%p%y(k), ps%p%r(k), dom, lk%span_j0(k), lk%span_nj(k), &
                        lk%span(:, :, k), lk%span_j0_old(k), lk%span_nj_old(k), &
                        lk%span_old(:, :, k))
      else
        call disk_spans(ps%p%x(k), ps%p%y(k), ps%p%r(k), dom, lk%span_j0(k), lk%span_nj(k), &
                        lk%span(:, :, k))
      end if
      do m = 1, lk%span_nj(k)
        j = lk%span_j0(k) + m - 1
        lk%solid(max(lk%span(1, m, k), 1):min(lk%span(2, m, k), dom%nx), j) = .true.
      end do
    end do
    lk%nplaced = ps%n
    lk%placed_y0 = dom%y0
    lk%placements = lk%placements + 1
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

  pure module subroutine disk_spans(x, y, r, dom, j0, nj, sp, gj0, gnj, gsp)
    real(wp), intent(in) :: x, y, r
    type(domain_t), intent(in) :: dom
    integer, intent(out) :: j0, nj
    integer, intent(inout) :: sp(:, :)
    integer, intent(in), optional :: gj0, gnj, gsp(:, :)
    !> runs to start from (of the same disk a little earlier): rows gj0.. (gnj rows)
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
  pure subroutine span_of(lk, k, j, lo, hi)
    type(links_t), intent(in) :: lk
    integer, intent(in) :: k, j
    integer, intent(out) :: lo, hi
    integer :: m
    m = j - lk%span_j0(k) + 1
    if (m >= 1 .and. m <= lk%span_nj(k)) then
      lo = lk%span(1, m, k)
      hi = lk%span(2, m, k)
    else
      lo = NO_LO
      hi = NO_HI
    end if
  end subroutine span_of

  pure logical module function old_spans_of(lk, dom, m, x, y, r) result(kept)
    type(links_t), intent(in) :: lk
    type(domain_t), intent(in) :: dom
    integer, intent(in) :: m
    real(wp), intent(in) :: x, y, r
    kept = m <= lk%nplaced_old .and. lk%placed_y0_old == dom%y0
    if (kept) kept = lk%placed_old(1, m) == x .and. lk%placed_old(2, m) == y .and. &
                     lk%placed_old(3, m) == r
  end function old_spans_of

  pure logical module function is_fluid(lk, ps, dom, i, jg)
    type(links_t), intent(in) :: lk
    type(particles_t), intent(in) :: ps
    type(domain_t), intent(in) :: dom
    integer, intent(in) :: i, jg
    is_fluid = i >= 1 .and. i <= dom%nx .and. (dom%periodic_y .or. (jg >= 1 .and. jg <= dom%ny))
    if (.not. is_fluid) return
    if (jg - dom%y0 >= 0 .and. jg - dom%y0 <= dom%nyl + 1) then
      is_fluid = mask_fluid(lk, dom, i, jg - dom%y0)
    else
      is_fluid = fluid_far(lk, ps, i, jg)
    end if
  end function is_fluid

  !> Whether the channel node (i, jg), beyond the mask's rows, lies outside every particle the
  !! slab holds: only the disks of the cells within rmax of the node are tested.
  pure logical function fluid_far(lk, ps, i, jg) result(fluid)
    type(links_t), intent(in) :: lk
    type(particles_t), intent(in) :: ps
    integer, intent(in) :: i, jg
    integer :: k, l, i1, i2, j1, j2, jc
    real(wp) :: px, py
    px = i - 0.5_wp
    py = jg - 0.5_wp
    call cells_box(lk%ncells, px, py, ps%rmax, i1, i2, j1, j2)
    if (i1 == 0) then
      fluid = .not. any([(inside_at(ps%p%x(k), ps%p%y(k), ps%p%r(k), px, py), k=1, ps%n)])
      return
    end if
    fluid = .true.
    associate (c => lk%ncells)
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
  pure logical function mask_fluid(lk, dom, i, j) result(fluid)
    type(links_t), intent(in) :: lk
    type(domain_t), intent(in) :: dom
    integer, intent(in) :: i, j
    fluid = i >= 1 .and. i <= dom%nx .and. &
            (dom%periodic_y .or. (dom%y0 + j >= 1 .and. dom%y0 + j <= dom%ny))
    if (fluid) fluid = .not. lk%solid(i, j)
  end function mask_fluid

  module subroutine search_links(lk, ps, dom)
    type(links_t), intent(inout) :: lk
    type(particles_t), intent(in) :: ps
    type(domain_t), intent(in) :: dom
    integer :: k, m, n, ne, n0, i1, i2, j1, j2, since
    integer :: room, room_e !! places in the arrays of the links, of the entries
    integer, allocatable :: was(:) !! the disk of the last search that disk k is, or 0
    logical, allocatable :: dirty(:, :), same(:), tl(:)
    logical :: kept
    call place_for_nodes(lk, ps, dom)
    ! the runs the last search read: the present ones when no disk was placed since, those of
    ! the placement before (the refill's, after the move) when one was; else every disk is
    ! searched
    since = lk%placements - lk%kept_placement
    kept = lk%kept_n >= 0 .and. lk%kept_y0 == dom%y0 .and. lk%kept_nx == dom%nx .and. &
           lk%kept_nyl == dom%nyl .and. since <= 1
    ! the links of the last search become the kept ones, their arrays take the new links
    call swap(lk%lx, lk%kept_lx)
    call swap(lk%ly, lk%kept_ly)
    call swap(lk%ld, lk%kept_ld)
    call swap(lk%lrow, lk%kept_lrow)
    call swap(lk%rj, lk%kept_rj)
    call swap(lk%rlink, lk%kept_rlink)
    call swap(lk%rfirst, lk%kept_rfirst)
    call swap(lk%rlast, lk%kept_rlast)
    call move_alloc(lk%lff, tl)
    call move_alloc(lk%kept_lff, lk%lff)
    call move_alloc(tl, lk%kept_lff)
    ! the blocks of nodes where the mask may have changed, and the disks whose runs did not
    allocate (was(ps%n), same(ps%n), dirty(0:(dom%nx + 3 + BLOCK)/BLOCK, &
                                           0:(dom%nyl + 3 + BLOCK)/BLOCK))
    dirty = .false.
    was = 0
    same = .false.
    if (kept) call kept_disks(lk, ps, dom, since, was, same, dirty)
    call fit_entries(lk, ps, max(ps%n, 1), 0)
    room = 0
    room_e = 0
    lk%rfirst(1:ps%n) = 1
    lk%rlast(1:ps%n) = 0
    n = 0
    ne = 0
    do k = 1, ps%n
      ! room for every link of k, and the eight written for each node: at most 8 from each node
      ! beside its runs, which span no more than 2 r + 4 columns of each of its rows and the
      ! two beyond them; an entry of the row sums for each of those rows
      m = n + 8*(lk%span_nj(k) + 2)*(int(min(2.0_wp*ps%p%r(k), 1.0e6_wp)) + 6)
      if (m > room) then
        call fit_links(lk, m, n)
        room = min(size(lk%lp), size(lk%lx), size(lk%ly), size(lk%ld), size(lk%lrow), &
                   size(lk%lq), size(lk%lff))
      end if
      if (ne + lk%span_nj(k) + 3 > room_e) then
        call fit_entries(lk, ps, ne + lk%span_nj(k) + 3, ne)
        room_e = min(size(lk%rk), size(lk%rj), size(lk%rlink) - 1, size(lk%rows, 2))
      end if
      if (same(k)) then
        call runs_box(lk%span(:, :, k), lk%span_j0(k), lk%span_nj(k), i1, i2, j1, j2)
        same(k) = .not. any(dirty(block_x(dom, i1 - 2):block_x(dom, i2 + 2), &
                                  block_y(dom, j1 - 2):block_y(dom, j2 + 2)))
      end if
      n0 = n
      if (same(k)) then
        call take_kept(lk, k, was(k), n, ne)
      else
        call disk_links(lk, dom, k, n, ne)
      end if
      lk%lp(n0 + 1:n) = k
    end do
    lk%nlinks = n
    lk%nrows = ne
    lk%rlink(ne + 1) = n + 1
    lk%searches = lk%searches + 1
    lk%links_found = lk%links_found + n
    call row_entries(lk, dom%nyl)
    call keep_runs(lk, ps, dom)
  end subroutine search_links

  !> The disks of the last search that the present ones are (was, by id), those whose runs are
  !! the same (same), and the blocks of nodes where the mask changed since (dirty): see
  !! search_links. since: the placements since the last search, 0 or 1.
  subroutine kept_disks(lk, ps, dom, since, was, same, dirty)
    type(links_t), intent(in) :: lk
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
      do k = 1, min(ps%n, lk%kept_n)
        was(k) = k
      end do
      same = was > 0
    else
      m = 1
      do k = 1, ps%n
        do while (m <= lk%kept_n)
          if (lk%kept_id(m) >= ps%p%id(k)) exit
          call note(lk%span_old(:, :, m), lk%span_j0_old(m), lk%span_nj_old(m))
          m = m + 1
        end do
        if (m <= lk%kept_n) then
          if (lk%kept_id(m) == ps%p%id(k)) then
            was(k) = m
            same(k) = lk%span_j0_old(m) == lk%span_j0(k) .and. &
                      lk%span_nj_old(m) == lk%span_nj(k)
            if (same(k)) same(k) = all(lk%span_old(:, 1:lk%span_nj(k), m) == &
                                       lk%span(:, 1:lk%span_nj(k), k))
            if (.not. same(k)) call note_change(m, k)
            m = m + 1
          end if
        end if
        if (was(k) == 0) call note(lk%span(:, :, k), lk%span_j0(k), lk%span_nj(k))
      end do
      do m = m, lk%kept_n
        call note(lk%span_old(:, :, m), lk%span_j0_old(m), lk%span_nj_old(m))
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
      do j = min(lk%span_j0_old(m), lk%span_j0(k)), &
        max(lk%span_j0_old(m) + lk%span_nj_old(m), lk%span_j0(k) + lk%span_nj(k)) - 1
        ol = NO_LO
        oh = NO_HI
        if (j >= lk%span_j0_old(m) .and. j < lk%span_j0_old(m) + lk%span_nj_old(m)) then
          ol = lk%span_old(1, j - lk%span_j0_old(m) + 1, m)
          oh = lk%span_old(2, j - lk%span_j0_old(m) + 1, m)
        end if
        call span_of(lk, k, j, nl, nh)
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
  subroutine fit_links(lk, m, keep)
    type(links_t), intent(inout) :: lk
    integer, intent(in) :: m, keep
    integer :: c
    logical, allocatable :: tl(:)
    c = max(m, 16)
    call fit_int(lk%lp, c, keep)
    call fit_int(lk%lx, c, keep)
    call fit_int(lk%ly, c, keep)
    call fit_int(lk%ld, c, keep)
    call fit_int(lk%lrow, c, keep)
    if (.not. allocated(lk%lq)) allocate (lk%lq(0))
    if (size(lk%lq) < c) then
      ! (q is computed after the search: nothing to keep)
      deallocate (lk%lq)
      allocate (lk%lq(max(c, 2*size(lk%lp))))
    end if
    if (.not. allocated(lk%lff)) allocate (lk%lff(0))
    if (size(lk%lff) < c) then
      allocate (tl(max(c, 2*size(lk%lff))))
      tl(1:keep) = lk%lff(1:keep)
      call move_alloc(tl, lk%lff)
    end if
  end subroutine fit_links

  !> Room for m row-sum entries and the particles' first and last entries, the first keep
  !! entries kept.
  subroutine fit_entries(lk, ps, m, keep)
    type(links_t), intent(inout) :: lk
    type(particles_t), intent(in) :: ps
    integer, intent(in) :: m, keep
    real(wp), allocatable :: tr(:, :)
    call fit_int(lk%rk, m, keep)
    call fit_int(lk%rj, m, keep)
    call fit_int(lk%rlink, m + 1, keep)
    if (size(lk%rows, 2) < size(lk%rk)) then
      allocate (tr(3, size(lk%rk)))
      call move_alloc(tr, lk%rows)
    end if
    call fit_int(lk%rfirst, ps%n, ps%n)
    call fit_int(lk%rlast, ps%n, ps%n)
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
  subroutine take_kept(lk, k, m, n, ne)
    type(links_t), intent(inout) :: lk
    integer, intent(in) :: k, m
    integer, intent(inout) :: n, ne
    integer :: e1, e2, f1, f2, c
    e1 = lk%kept_rfirst(m)
    e2 = lk%kept_rlast(m)
    if (e1 > e2) return
    f1 = lk%kept_rlink(e1)
    f2 = lk%kept_rlink(e2 + 1) - 1
    c = f2 - f1 + 1
    call copy_links(c, ne + 1 - e1, lk%kept_lx(f1:f2), lk%kept_ly(f1:f2), lk%kept_ld(f1:f2), &
                    lk%kept_lff(f1:f2), lk%kept_lrow(f1:f2), lk%lx(n + 1:n + c), &
                    lk%ly(n + 1:n + c), lk%ld(n + 1:n + c), lk%lff(n + 1:n + c), &
                    lk%lrow(n + 1:n + c))
    lk%rk(ne + 1:ne + e2 - e1 + 1) = k
    lk%rj(ne + 1:ne + e2 - e1 + 1) = lk%kept_rj(e1:e2)
    lk%rlink(ne + 1:ne + e2 - e1 + 1) = lk%kept_rlink(e1:e2) + (n + 1 - f1)
    lk%rfirst(k) = ne + 1
    lk%rlast(k) = ne + e2 - e1 + 1
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
  subroutine keep_runs(lk, ps, dom)
    type(links_t), intent(inout) :: lk
    type(particles_t), intent(in) :: ps
    type(domain_t), intent(in) :: dom
    call fit_int(lk%kept_id, ps%n, 0)
    lk%kept_id(1:ps%n) = ps%p%id(1:ps%n)
    lk%kept_n = ps%n
    lk%kept_placement = lk%placements
    lk%kept_y0 = dom%y0
    lk%kept_nx = dom%nx
    lk%kept_nyl = dom%nyl
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
  subroutine disk_links(lk, dom, k, n, ne)
    type(links_t), intent(inout) :: lk
    type(domain_t), intent(in) :: dom
    integer, intent(in) :: k
    integer, intent(inout) :: n, ne
    integer :: j, l, m, n0, nr, lo(-1:1), hi(-1:1), a(8), b(8)
    n0 = n
    associate (lx => lk%lx, ly => lk%ly, ld => lk%ld, j0 => lk%span_j0(k), &
               nj => lk%span_nj(k))
      do j = max(1, j0 - 1), min(dom%nyl, j0 + nj)
        do m = -1, 1
          lo(m) = NO_LO
          hi(m) = NO_HI
          if (j + m >= j0 .and. j + m < j0 + nj) then
            lo(m) = lk%span(1, j + m - j0 + 1, k)
            hi(m) = lk%span(2, j + m - j0 + 1, k)
          end if
        end do
        ! the neighbour x_f + e_d of node i lies inside k when a(d) <= i <= b(d)
        a = lo(ey(1:8)) - ex(1:8)
        b = hi(ey(1:8)) - ex(1:8)
        nr = n
        ! (a node outside the channel is not fluid)
        if (dom%periodic_y .or. (dom%y0 + j >= 1 .and. dom%y0 + j <= dom%ny)) &
          call row_links(max(1, minval(lo) - 1), min(dom%nx, maxval(hi) + 1), lo(0), hi(0), &
                         a, b, lk%solid(:, j), lx, ld, n)
        if (n > nr) then
          ne = ne + 1
          if (n0 == nr) lk%rfirst(k) = ne
          lk%rlast(k) = ne
          lk%rk(ne) = k
          lk%rj(ne) = j
          lk%rlink(ne) = nr + 1
          ly(nr + 1:n) = j
          lk%lrow(nr + 1:n) = ne
        end if
      end do
      do l = n0 + 1, n
        lk%lff(l) = mask_fluid(lk, dom, lx(l) - ex(ld(l)), ly(l) - ey(ld(l)))
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
  subroutine row_entries(lk, nyl)
    type(links_t), intent(inout) :: lk
    integer, intent(in) :: nyl !! rows of the slab
    integer :: l, k, n, m
    lk%rows(:, 1:lk%nrows) = 0.0_wp
    if (.not. allocated(lk%lstart)) allocate (lk%lstart(0))
    if (size(lk%lstart) /= nyl + 1) then
      deallocate (lk%lstart)
      allocate (lk%lstart(nyl + 1))
    end if
    if (.not. allocated(lk%lorder)) allocate (lk%lorder(0))
    if (size(lk%lorder) < lk%nlinks) then
      deallocate (lk%lorder)
      allocate (lk%lorder(max(lk%nlinks, 2*size(lk%lp))))
    end if
    ! a stable counting sort, taken entry by entry: the links of an entry are a run of one row,
    ! so each entry adds its run to its row's count and then copies it in one piece
    associate (lstart => lk%lstart, lorder => lk%lorder, rj => lk%rj, first => lk%rlink)
      lstart = 0
      do n = 1, lk%nrows
        lstart(rj(n)) = lstart(rj(n)) + (first(n + 1) - first(n))
      end do
      m = 1
      do k = 1, nyl + 1
        n = lstart(k)
        lstart(k) = m
        m = m + n
      end do
      do n = 1, lk%nrows
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
end submodule dkt_links_search

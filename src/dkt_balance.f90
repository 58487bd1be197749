!> Slabs that follow the load (docs/design.md, "Balanced slabs"): the modelled cost of each
!> global row, and the borders that split the rows over the ranks so that the costliest slab
!> costs as little as it can, every slab keeping at least a given number of rows.
!>
!> The cost of a row is the cost model of docs/performance.md ("A cost model"): a per cell, b
!> per boundary link, c per node inside a disk, d per disk and contact sub-step, a disk counted
!> in the row of its centre. Every rank computes the split from the same costs (each
!> rank's rows gathered in order), so every rank finds the same borders. Results do not depend
!> on the borders (every split gives the same bits), only the speed does.
module dkt_balance
  use dkt_kinds, only: wp
  use, intrinsic :: ieee_arithmetic, only: ieee_is_finite
  use dkt_domain, only: domain_t, domain_gather_rows, domain_row_at
  use dkt_particles, only: particles_t
  use dkt_links, only: links_t, links_row_work
  implicit none
  private
  public :: balance_row_costs, balance_split, balance_imbalance, balance_plan, balance_line

  !> the cost model's coefficients, ns: a cell, a boundary link (found, q and bounced), a node
  !! inside a disk (the refill's scan; the reset waits for a read), a disk and contact sub-step,
  !! fitted to the `time per part` of 1-rank runs of sediment504 at 8 per D and bidisperse at 10
  !! per D (docs/performance.md, "Balanced slabs"). Only their ratios move the borders.
  real(wp), parameter :: A_CELL = 3.4_wp, B_LINK = 17.3_wp, C_INTERIOR = 2.3_wp, &
                         D_SUBSTEP = 90.0_wp

contains

  !> The borders a balanced split would give the slabs of `dom` now (every rank alike): the
  !! modelled cost of every row from its cells, the links of the last search, the nodes inside
  !! the disks and the disks this slab owns (with `substeps` contact sub-steps), gathered in
  !! row order; the imbalance of the present split (`before`) and of the one found (`after`).
  !! `starts` is the present split when it is within `threshold` or no split with slabs of
  !! at least min_rows rows does better by more than 2 %.
  subroutine balance_plan(lk, ps, dom, substeps, min_rows, threshold, starts, before, after)
    type(links_t), intent(in) :: lk
    type(particles_t), intent(in) :: ps
    type(domain_t), intent(in) :: dom
    integer, intent(in) :: substeps, min_rows
    real(wp), intent(in) :: threshold
    integer, intent(out) :: starts(0:dom%nranks)
    real(wp), intent(out) :: before, after
    integer :: links(dom%nyl), nodes(dom%nyl), disks(dom%nyl), k, j
    real(wp) :: every(dom%ny)
    call links_row_work(lk, dom, links, nodes)
    disks = 0
    do k = 1, ps%n
      if (ps%home(k) /= dom%rank .or. .not. ieee_is_finite(ps%p%y(k))) cycle
      j = domain_row_at(dom, ps%p%y(k)) - dom%y0
      if (j >= 1 .and. j <= dom%nyl) disks(j) = disks(j) + 1
    end do
    call domain_gather_rows(dom, balance_row_costs(dom%nx, links, nodes, disks, substeps), every)
    starts = dom%starts
    before = balance_imbalance(every, starts)
    after = before
    if (before <= threshold) return
    starts = balance_split(every, dom%nranks, min_rows)
    after = balance_imbalance(every, starts)
    if (after > 0.98_wp*before) then
      starts = dom%starts
      after = before
    end if
  end subroutine balance_plan

  !> The log line of a balance check at step n: the rows per rank before and after, and the
  !! modelled imbalance of each split.
  function balance_line(n, old, new, before, after) result(line)
    integer, intent(in) :: n, old(0:), new(0:)
    real(wp), intent(in) :: before, after
    character(len=:), allocatable :: line
    character(len=32) :: w
    integer :: r
    write (w, '(i0)') n
    line = 'balance at step '//trim(w)//': rows per rank'
    do r = 1, size(old) - 1
      write (w, '(1x,i0)') old(r) - old(r - 1)
      line = line//trim(w)
    end do
    line = line//' ->'
    do r = 1, size(new) - 1
      write (w, '(1x,i0)') new(r) - new(r - 1)
      line = line//trim(w)
    end do
    write (w, '(f0.2,a,f0.2)') before, ' -> ', after
    line = line//' (modelled imbalance, the costliest slab over the mean: '//trim(w)//')'
  end function balance_line

  !> The modelled cost (ns) of each row of a slab of nx columns: links(j) boundary links,
  !! nodes(j) nodes inside disks and disks(j) disk centres in row j, substeps contact sub-steps.
  pure function balance_row_costs(nx, links, nodes, disks, substeps) result(cost)
    integer, intent(in) :: nx, links(:), nodes(:), disks(:), substeps
    real(wp) :: cost(size(links))
    cost = A_CELL*nx + B_LINK*links + C_INTERIOR*nodes + D_SUBSTEP*substeps*disks
  end function balance_row_costs

  !> The costliest slab of the split `starts` (rank r: rows starts(r)+1 .. starts(r+1)) over
  !! the mean slab: 1 for a perfect balance.
  pure real(wp) function balance_imbalance(cost, starts) result(ratio)
    real(wp), intent(in) :: cost(:)
    integer, intent(in) :: starts(0:)
    real(wp) :: most
    integer :: r, n
    n = size(starts) - 1
    most = 0.0_wp
    do r = 0, n - 1
      most = max(most, sum(cost(starts(r) + 1:starts(r + 1))))
    end do
    ratio = most/max(sum(cost)/n, tiny(1.0_wp))
  end function balance_imbalance

  !> Borders that split the rows of `cost` over n ranks, each slab at least min_rows rows
  !! (n min_rows <= size(cost)), so that the costliest slab costs least: the smallest
  !! capacity (a bisection) for which some split keeps every slab within it (fill).
  pure function balance_split(cost, n, min_rows) result(starts)
    real(wp), intent(in) :: cost(:)
    integer, intent(in) :: n, min_rows
    integer :: starts(0:n), trial(0:n)
    real(wp) :: lo, hi, mid, pre(0:size(cost))
    integer :: it, j
    logical :: ok
    pre(0) = 0.0_wp
    do j = 1, size(cost)
      pre(j) = pre(j - 1) + cost(j)
    end do
    lo = 0.0_wp
    hi = 2.0_wp*pre(size(cost))
    ! (hi always fits: any split of slabs of at least min_rows rows does)
    call fill(pre, n, min_rows, hi, starts, ok)
    do it = 1, 100
      mid = 0.5_wp*(lo + hi)
      if (mid <= lo .or. mid >= hi) exit
      call fill(pre, n, min_rows, mid, trial, ok)
      if (ok) then
        hi = mid
        starts = trial
      else
        lo = mid
      end if
    end do
  end function balance_split

  !> Whether n slabs of at least min_rows rows, each costing at most `capacity`, can split the
  !! rows whose cost sums are pre(j) (rows 1..j), and such a split: the borders reachable after
  !! r slabs follow from those after r - 1 (a border i reaches j when j - i >= min_rows and
  !! rows i+1..j cost at most the capacity), then the split is taken back from the last row,
  !! each border the highest that reaches the next.
  pure subroutine fill(pre, n, min_rows, capacity, starts, ok)
    real(wp), intent(in) :: pre(0:), capacity
    integer, intent(in) :: n, min_rows
    integer, intent(out) :: starts(0:n)
    logical, intent(out) :: ok
    logical, allocatable :: reach(:, :) !! (border, slabs): border reached after that many
    integer, allocatable :: held(:) !! held(i): the borders below i reached by the last count
    integer :: r, i, j, ny, low
    ny = size(pre) - 1
    allocate (reach(0:ny, 0:n), held(0:ny + 1))
    reach = .false.
    reach(0, 0) = .true.
    do r = 1, n
      held(0) = 0
      do i = 0, ny
        held(i + 1) = held(i) + merge(1, 0, reach(i, r - 1))
      end do
      low = 0
      do j = min_rows, ny
        ! the lowest border from which rows low+1..j fit (it rises with j)
        do while (pre(j) - pre(low) > capacity)
          low = low + 1
        end do
        if (low <= j - min_rows) reach(j, r) = held(j - min_rows + 1) > held(low)
      end do
    end do
    ok = reach(ny, n)
    starts(0) = 0
    starts(n) = ny
    if (.not. ok) return
    j = ny
    do r = n, 2, -1
      do i = j - min_rows, 0, -1
        if (pre(j) - pre(i) > capacity) exit
        if (reach(i, r - 1)) exit
      end do
      starts(r - 1) = i
      j = i
    end do
  end subroutine fill
end module dkt_balance

!> Cell lists of disk centres: a grid of square cells over the centres, each cell listing its
!> disks in ascending index order, so that the disks within a given reach of a point are found
!> in time independent of the number of disks. The short-range forces (E10–E11) and the
!> search for boundary links use it in place of a loop over every disk (docs/running.md,
!> "Scenes of many particles").
!>
!> Nothing wraps: the contact law and the link search measure plain distances, also in a
!> periodic channel. A centre that is not finite or lies beyond +-1e100 (where a cell index would
!> overflow) goes to a list of its own, which every query returns; so a query gives exactly the
!> disks a loop over all would have to look at, plus some beyond the reach, in ascending index
!> order.
module dkt_cells
  use, intrinsic :: ieee_arithmetic, only: ieee_is_finite
  use dkt_kinds, only: wp
  implicit none
  private
  public :: cells_t, cells_build, cells_near, cells_candidates, cells_box, sort_ascending

  !> The largest |coordinate| a centre or a query point may have to be placed in a cell.
  real(wp), parameter :: FAR = 1.0e100_wp

  type :: cells_t
    integer :: n = 0                  !! disks listed
    real(wp) :: x0 = 0, y0 = 0        !! lower left corner of cell (1, 1)
    real(wp) :: side = 1              !! side of a cell
    integer :: nx = 1, ny = 1         !! cells across (x) and along (y)
    integer, allocatable :: start(:)  !! the disks of cell c are items(start(c):start(c + 1) - 1)
    integer, allocatable :: items(:)  !! disk indices by cell, ascending within a cell
    integer, allocatable :: stray(:)  !! disks in no cell (a centre beyond FAR), ascending
  end type cells_t

contains

  !> Place the centres (x, y) in cells of side at least side_min (wider when the centres are so
  !! spread that there would be more than about 4 cells a disk): O(n) time and memory. The
  !! arrays of c are kept from one build to the next while their sizes stay.
  pure subroutine cells_build(c, x, y, side_min)
    type(cells_t), intent(inout) :: c
    real(wp), intent(in) :: x(:), y(:)  !! centres
    real(wp), intent(in) :: side_min    !! the smallest side of a cell
    logical :: placed(size(x))
    integer :: k, nplaced, cell(size(x))
    real(wp) :: xmax, ymax
    c%n = size(x)
    ! the corner and the far end of the placed centres: the first placed centre, then each
    ! smaller (larger) one, as minval and maxval take them
    c%x0 = 0; c%y0 = 0; xmax = 0; ymax = 0
    nplaced = 0
    do k = 1, c%n
      placed(k) = near_origin(x(k)) .and. near_origin(y(k))
      if (.not. placed(k)) cycle
      nplaced = nplaced + 1
      if (nplaced == 1) then
        c%x0 = x(k); c%y0 = y(k); xmax = x(k); ymax = y(k)
      else
        if (x(k) < c%x0) c%x0 = x(k)
        if (y(k) < c%y0) c%y0 = y(k)
        if (x(k) > xmax) xmax = x(k)
        if (y(k) > ymax) ymax = y(k)
      end if
    end do
    call fit(c%stray, c%n - nplaced)
    if (nplaced < c%n) c%stray = pack([(k, k=1, c%n)],.not. placed)
    c%side = side_min
    if (.not. (c%side > 0.0_wp .and. c%side <= FAR)) c%side = 1.0_wp
    do while (((xmax - c%x0)/c%side + 1.0_wp)*((ymax - c%y0)/c%side + 1.0_wp) > 4.0_wp*c%n + 16)
      c%side = 2.0_wp*c%side
    end do
    c%nx = int((xmax - c%x0)/c%side) + 1
    c%ny = int((ymax - c%y0)/c%side) + 1
    ! counting sort by cell; taking the disks in index order keeps each cell ascending
    call fit(c%start, c%nx*c%ny + 1)
    c%start = 0
    do k = 1, c%n
      if (.not. placed(k)) cycle
      cell(k) = slot(c, x(k), c%x0, c%nx) + c%nx*(slot(c, y(k), c%y0, c%ny) - 1)
      c%start(cell(k) + 1) = c%start(cell(k) + 1) + 1
    end do
    c%start(1) = 1
    do k = 2, size(c%start)
      c%start(k) = c%start(k) + c%start(k - 1)
    end do
    call fit(c%items, nplaced)
    do k = 1, c%n
      if (.not. placed(k)) cycle
      c%items(c%start(cell(k))) = k
      c%start(cell(k)) = c%start(cell(k)) + 1
    end do
    ! each start now points at the next cell's first disk: shift back by one cell
    do k = size(c%start), 2, -1
      c%start(k) = c%start(k - 1)
    end do
    c%start(1) = 1
  contains
    !> Make a exactly n long (its values are set after).
    pure subroutine fit(a, n)
      integer, allocatable, intent(inout) :: a(:)
      integer, intent(in) :: n
      if (allocated(a)) then
        if (size(a) == n) return
        deallocate (a)
      end if
      allocate (a(n))
    end subroutine fit
  end subroutine cells_build

  !> The disks whose centres may lie within reach of (px, py): near(1:m), ascending, every disk
  !! within reach among them (every disk when the point or the reach cannot be placed).
  subroutine cells_near(c, px, py, reach, near, m)
    type(cells_t), intent(in) :: c
    real(wp), intent(in) :: px, py, reach
    integer, allocatable, intent(inout) :: near(:) !! grown as needed
    integer, intent(out) :: m
    call cells_candidates(c, px, py, reach, near, m)
    call sort_ascending(near, m)
  end subroutine cells_near

  !> Sort list(1:m) ascending by insertion: the lists sorted here are short (the disks of a few
  !! cells, a disk's contact partners).
  pure subroutine sort_ascending(list, m)
    integer, intent(inout) :: list(:)
    integer, intent(in) :: m
    integer :: k, l, a
    do l = 2, m
      a = list(l)
      k = l - 1
      do while (k >= 1)
        if (list(k) < a) exit
        list(k + 1) = list(k)
        k = k - 1
      end do
      list(k + 1) = a
    end do
  end subroutine sort_ascending

  !> The disks of cells_near in no particular order (the cells' ones row of cells by row of
  !! cells, then the stray disks), each once: for a caller that keeps a few of them.
  subroutine cells_candidates(c, px, py, reach, near, m)
    type(cells_t), intent(in) :: c
    real(wp), intent(in) :: px, py, reach
    integer, allocatable, intent(inout) :: near(:) !! grown as needed
    integer, intent(out) :: m
    integer :: i1, i2, j1, j2, j, k, l, first, last
    call cells_box(c, px, py, reach, i1, i2, j1, j2)
    if (i1 == 0) then
      call fit(c%n)
      near(1:c%n) = [(k, k=1, c%n)]
      m = c%n
      return
    end if
    ! the cells i1..i2 of a row of cells are one run of items: the runs of the rows j1..j2 and
    ! the stray disks, one after the other (each disk is in one cell or stray)
    m = size(c%stray)
    do j = j1, j2
      m = m + c%start(i2 + 1 + c%nx*(j - 1)) - c%start(i1 + c%nx*(j - 1))
    end do
    call fit(m)
    l = 0
    do j = j1, j2
      first = c%start(i1 + c%nx*(j - 1))
      last = c%start(i2 + 1 + c%nx*(j - 1)) - 1
      near(l + 1:l + last - first + 1) = c%items(first:last)
      l = l + last - first + 1
    end do
    near(l + 1:m) = c%stray
  contains
    subroutine fit(size_needed)
      integer, intent(in) :: size_needed
      if (allocated(near)) then
        if (size(near) >= size_needed) return
        deallocate (near)
      end if
      allocate (near(max(64, 2*size_needed)))
    end subroutine fit
  end subroutine cells_candidates

  !> The cells i1..i2 across and j1..j2 along that hold every centre within reach of (px, py),
  !! with a relative margin for rounding; i1 = 0 when the point or the reach is too large or not
  !! finite to be placed (then every disk may be within reach).
  pure subroutine cells_box(c, px, py, reach, i1, i2, j1, j2)
    type(cells_t), intent(in) :: c
    real(wp), intent(in) :: px, py, reach
    integer, intent(out) :: i1, i2, j1, j2
    real(wp) :: r
    i1 = 0; i2 = -1; j1 = 0; j2 = -1
    if (.not. (near_origin(px) .and. near_origin(py) .and. near_origin(reach))) return
    r = reach + 1.0e-9_wp*(abs(reach) + abs(px) + abs(py))
    i1 = slot(c, px - r, c%x0, c%nx)
    i2 = slot(c, px + r, c%x0, c%nx)
    j1 = slot(c, py - r, c%y0, c%ny)
    j2 = slot(c, py + r, c%y0, c%ny)
  end subroutine cells_box

  !> The cell, 1..cells, of coordinate v along an axis whose first cell starts at v0: clipped
  !! to the grid, so monotone in v (a centre within reach of a point is never outside the box).
  pure integer function slot(c, v, v0, cells)
    type(cells_t), intent(in) :: c
    real(wp), intent(in) :: v, v0
    integer, intent(in) :: cells
    slot = int(min(max((v - v0)/c%side, 0.0_wp), real(cells - 1, wp))) + 1
  end function slot

  !> Whether a coordinate is finite and within +-FAR, so that it can be placed in a cell.
  elemental logical function near_origin(v)
    real(wp), intent(in) :: v
    near_origin = ieee_is_finite(v)
    if (near_origin) near_origin = abs(v) <= FAR
  end function near_origin

end module dkt_cells

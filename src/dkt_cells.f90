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
  public :: cells_t, cells_build, cells_near, cells_box

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
  !! spread that there would be more than about 4 cells a disk): O(n) time and memory.
  pure subroutine cells_build(c, x, y, side_min)
    type(cells_t), intent(inout) :: c
    real(wp), intent(in) :: x(:), y(:)  !! centres
    real(wp), intent(in) :: side_min    !! the smallest side of a cell
    logical :: placed(size(x))
    integer :: k, cell(size(x))
    real(wp) :: xmax, ymax
    c%n = size(x)
    placed = near_origin(x) .and. near_origin(y)
    c%stray = pack([(k, k=1, c%n)],.not. placed)
    c%x0 = 0; c%y0 = 0; xmax = 0; ymax = 0
    if (any(placed)) then
      c%x0 = minval(x, mask=placed)
      c%y0 = minval(y, mask=placed)
      xmax = maxval(x, mask=placed)
      ymax = maxval(y, mask=placed)
    end if
    c%side = side_min
    if (.not. (c%side > 0.0_wp .and. c%side <= FAR)) c%side = 1.0_wp
    do while (((xmax - c%x0)/c%side + 1.0_wp)*((ymax - c%y0)/c%side + 1.0_wp) > 4.0_wp*c%n + 16)
      c%side = 2.0_wp*c%side
    end do
    c%nx = int((xmax - c%x0)/c%side) + 1
    c%ny = int((ymax - c%y0)/c%side) + 1
    ! counting sort by cell; taking the disks in index order keeps each cell ascending
    if (allocated(c%start)) deallocate (c%start)
    allocate (c%start(c%nx*c%ny + 1))
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
    if (allocated(c%items)) deallocate (c%items)
    allocate (c%items(count(placed)))
    do k = 1, c%n
      if (.not. placed(k)) cycle
      c%items(c%start(cell(k))) = k
      c%start(cell(k)) = c%start(cell(k)) + 1
    end do
    ! each start now points at the next cell's first disk: shift back by one cell
    c%start(2:) = c%start(1:size(c%start) - 1)
    c%start(1) = 1
  end subroutine cells_build

  !> The disks whose centres may lie within reach of (px, py): near(1:m), ascending, every disk
  !! within reach among them (every disk when the point or the reach cannot be placed).
  subroutine cells_near(c, px, py, reach, near, m)
    type(cells_t), intent(in) :: c
    real(wp), intent(in) :: px, py, reach
    integer, allocatable, intent(inout) :: near(:) !! grown as needed
    integer, intent(out) :: m
    integer :: i1, i2, j1, j2, k
    call cells_box(c, px, py, reach, i1, i2, j1, j2)
    if (i1 == 0) then
      call fit(c%n)
      near(1:c%n) = [(k, k=1, c%n)]
      m = c%n
    else
      call merge((i2 - i1 + 1)*(j2 - j1 + 1) + 1)
    end if
  contains
    !> Merge the ascending lists of the cells i1..i2 x j1..j2 and the stray disks (the last list).
    subroutine merge(lists)
      integer, intent(in) :: lists
      integer :: head(lists), tail(lists), i, j, l, pick
      l = 0
      do j = j1, j2
        do i = i1, i2
          l = l + 1
          head(l) = c%start(i + c%nx*(j - 1))
          tail(l) = c%start(i + c%nx*(j - 1) + 1)
        end do
      end do
      head(lists) = 1
      tail(lists) = size(c%stray) + 1
      call fit(sum(tail - head))
      m = 0
      do
        pick = 0
        do l = 1, lists
          if (head(l) >= tail(l)) cycle
          if (pick == 0) then
            pick = l
          else if (item(l, head(l), lists) < item(pick, head(pick), lists)) then
            pick = l
          end if
        end do
        if (pick == 0) exit
        m = m + 1
        near(m) = item(pick, head(pick), lists)
        head(pick) = head(pick) + 1
      end do
    end subroutine merge
    !> Entry h of list l: of the cells' items, or of the stray disks for the last list.
    pure integer function item(l, h, lists)
      integer, intent(in) :: l, h, lists
      if (l == lists) then
        item = c%stray(h)
      else
        item = c%items(h)
      end if
    end function item
    subroutine fit(size_needed)
      integer, intent(in) :: size_needed
      if (allocated(near)) then
        if (size(near) >= size_needed) return
        deallocate (near)
      end if
      allocate (near(max(64, 2*size_needed)))
    end subroutine fit
  end subroutine cells_near

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

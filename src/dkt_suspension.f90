!> The statistics of a settling suspension (docs/suspensions.md), from the particles' centres,
!> radii and velocities in physical units: the mean and root-mean-square settling velocity of
!> the free disks, the height of the upper front, the area-fraction profile phi(y), and with
!> two sizes a segregation index. The output writes them to /suspension at every particle
!> sample of a scene of three particles or more.
module dkt_suspension
  use ieee_arithmetic, only: ieee_is_finite
  use dkt_kinds, only: wp, pi
  implicit none
  private
  public :: suspension_stats, suspension_bins, FRONT_FRACTION, heap_sort

  !> the upper front: the height below which this fraction of the disks' centres lie
  real(wp), parameter :: FRONT_FRACTION = 0.95_wp

contains

  !> The number of bins of height `bin` that cover a box of height `height` (at least one).
  pure integer function suspension_bins(height, bin) result(nb)
    real(wp), intent(in) :: height, bin
    nb = max(1, ceiling(height/bin - 1.0e-9_wp))
  end function suspension_bins

  !> stats = [v_mean, v_rms, front, segregation]: the mean of the free disks' vertical velocity
  !! v, the root mean square of v over them (both 0 when none is free), the height below which
  !! FRONT_FRACTION of all centres lie, and, when the disks have exactly two sizes, (mean y of
  !! the small ones - mean y of the large ones)/height (> 0: the small ones above; 0 with one
  !! size or more than two). phi(b) is the area of the disks within bin b (heights
  !! (b-1) bin .. b bin) over the bin's area, the disks cut exactly by the bin's lines.
  pure subroutine suspension_stats(y, v, r, free, width, height, bin, stats, phi)
    real(wp), intent(in) :: y(:), v(:), r(:)  !! centres' heights, velocities, radii (cm, cm/s)
    logical, intent(in) :: free(:)            !! the disk moves freely (not fixed or prescribed)
    real(wp), intent(in) :: width, height, bin !! the box and the bin height (cm)
    real(wp), intent(out) :: stats(4)
    real(wp), intent(out) :: phi(:)           !! suspension_bins(height, bin) values
    real(wp) :: small, large, ys, yl
    real(wp), allocatable :: sorted(:)
    logical :: finite(size(y))
    integer :: k, b, b1, b2, nf
    nf = count(free)
    stats = 0.0_wp
    if (nf > 0) then
      stats(1) = sum(v, mask=free)/nf
      stats(2) = sqrt(sum(v**2, mask=free)/nf)
    end if
    ! (a centre that is not finite, in the output of a run a guard stopped, counts nowhere:
    ! an ordered comparison with NaN traps in the checked build)
    finite = ieee_is_finite(y)
    if (count(finite) > 0) then
      sorted = pack(y, finite)
      call heap_sort(sorted)
      stats(3) = sorted(max(1, ceiling(FRONT_FRACTION*size(sorted))))
      small = minval(r)
      large = maxval(r)
      if (large > small .and. all(r == small .or. r == large)) then
        ys = sum(y, mask=r == small .and. finite)/max(1, count(r == small .and. finite))
        yl = sum(y, mask=r == large .and. finite)/max(1, count(r == large .and. finite))
        stats(4) = (ys - yl)/height
      end if
    end if
    phi = 0.0_wp
    do k = 1, size(y)
      if (.not. finite(k)) cycle
      b1 = max(1, floor(max(y(k) - r(k), -bin)/bin) + 1)
      b2 = min(size(phi), floor(min(y(k) + r(k), (size(phi) + 1)*bin)/bin) + 1)
      do b = b1, b2
        phi(b) = phi(b) + below(y(k), r(k), b*bin) - below(y(k), r(k), (b - 1)*bin)
      end do
    end do
    phi = phi/(bin*width)
  contains
    !> The area of the disk of centre height c and radius rr below the line y = h.
    pure real(wp) function below(c, rr, h)
      real(wp), intent(in) :: c, rr, h
      real(wp) :: t
      t = min(max((h - c)/rr, -1.0_wp), 1.0_wp)
      below = rr*rr*(asin(t) + t*sqrt(1.0_wp - t*t) + 0.5_wp*pi)
    end function below
  end subroutine suspension_stats

  !> Sort a in ascending order (heapsort: O(n log n), no recursion, no extra memory).
  pure subroutine heap_sort(a)
    real(wp), intent(inout) :: a(:)
    integer :: n, i
    real(wp) :: t
    n = size(a)
    do i = n/2, 1, -1
      call sift(a, i, n)
    end do
    do i = n, 2, -1
      t = a(1)
      a(1) = a(i)
      a(i) = t
      call sift(a, 1, i - 1)
    end do
  end subroutine heap_sort

  !> Move a(first) down the heap a(first..last) until neither child is larger.
  pure subroutine sift(a, first, last)
    real(wp), intent(inout) :: a(:)
    integer, intent(in) :: first, last
    integer :: root, child
    real(wp) :: t
    root = first
    do
      child = 2*root
      if (child > last) exit
      if (child < last) then
        if (a(child + 1) > a(child)) child = child + 1
      end if
      if (a(root) >= a(child)) exit
      t = a(root)
      a(root) = a(child)
      a(child) = t
      root = child
    end do
  end subroutine sift

end module dkt_suspension

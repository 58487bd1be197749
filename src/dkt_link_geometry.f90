!> The two computations on a disk whose rounding the links carry (docs/model.md §3): whether a
!> node lies inside a disk, and the fraction q of a link that lies in the fluid.
!>
!> A compiler fuses a product into a following sum (a fused multiply-add, one rounding instead
!> of two) depending on the code around the expression: which products it has already computed
!> for other uses, and where it has moved them out of a loop. Each computation here is compiled
!> alone, so that every caller gets the bits of the expression as written; the callers are in
!> other modules, where it is never inlined. dkt_links_search decides most nodes without the
!> call (inside_at). link_fractions takes q of many links in one loop: every input of a link,
!> its disk's centre and radius too, is read per link, so that no product of the formula is
!> shared between links or moved out of the loop, and each link's q has the bits of one call.
module dkt_link_geometry
  use dkt_kinds, only: wp
  use dkt_lattice, only: ex, ey
  implicit none
  private
  public :: disk_inside, link_fraction, link_fractions

  !> 1/|e_d|^2 of the moving directions: 1 along the axes, 1/2 (exact) along the diagonals
  real(wp), parameter :: inv_e2(1:8) = 1.0_wp/real(ex(1:8)**2 + ey(1:8)**2, wp)

contains

  !> Whether the point (px, py) lies strictly inside the disk (x, y) of radius r.
  pure logical function disk_inside(x, y, r, px, py) result(inside)
    real(wp), intent(in) :: x, y, r, px, py
    inside = (px - x)**2 + (py - y)**2 < r**2
  end function disk_inside

  !> The fraction t in (0, 1] of the link from the point (px, py), outside the disk (x, y) of
  !! radius r, along e_d that lies outside the disk: |x + t e - X|^2 = r^2, the smaller root.
  pure real(wp) function link_fraction(x, y, r, px, py, d) result(q)
    real(wp), intent(in) :: x, y, r, px, py
    integer, intent(in) :: d
    real(wp) :: dxp, dyp, b, c, t
    dxp = px - x
    dyp = py - y
    b = dxp*ex(d) + dyp*ey(d)
    c = dxp*dxp + dyp*dyp - r*r
    ! |e_d|^2 is 1 or 2: the division by it is the exact product with 1 or 1/2
    t = (-b - sqrt(max(b*b - (ex(d)**2 + ey(d)**2)*c, 0.0_wp)))*inv_e2(d)
    q = min(max(t, 1.0e-6_wp), 1.0_wp)
  end function link_fraction

  !> link_fraction of links 1..n: from node (i(l), local row j(l)) of a slab whose first row is
  !! y0 + 1 along d(l), of disk k(l) of centres (x, y) and radii r.
  pure subroutine link_fractions(n, k, i, j, d, y0, x, y, r, q)
    integer, intent(in) :: n, y0
    integer, intent(in), contiguous :: k(:), i(:), j(:), d(:)
    real(wp), intent(in), contiguous :: x(:), y(:), r(:)
    real(wp), intent(inout), contiguous :: q(:)
    integer :: l
    do l = 1, n
      q(l) = link_fraction(x(k(l)), y(k(l)), r(k(l)), i(l) - 0.5_wp, y0 + j(l) - 0.5_wp, d(l))
    end do
  end subroutine link_fractions
end module dkt_link_geometry

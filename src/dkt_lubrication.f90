!> The lubrication correction (docs/model.md §4, E13): the normal force of the thin film between
!> two disks, or between a disk and a wall, for the part of the gap the lattice does not resolve.
!> Reynolds' lubrication theory for two cylinders of radii a_1, a_2 (per unit depth) with a gap
!> h much smaller than both gives F = 3 sqrt(2) pi mu (a*/h)^(3/2) V, a* = a_1 a_2/(a_1 + a_2)
!> (a* = a against a plane wall), V the rate at which the gap closes. The lattice resolves the
!> film down to a gap of about a spacing, so the correction adds only the difference between
!> the theory at h and at the cut-off h_c:
!>   C(h) = 3 sqrt(2) pi mu a*^(3/2) (h^(-3/2) - h_c^(-3/2))  for h < h_c, 0 beyond,
!> with h no smaller than h_min (a roughness: the film never closes). The force on a disk is
!> -C(h) ((U - U_partner) . n) n, n the unit vector from the partner's centre (or the wall) to
!> the disk's: it resists the approach and the separation alike. Its stiffness grows without
!> bound as h shrinks, so the motion takes it implicitly in the disk's own velocity
!> (lubrication_matrix, dkt_particle_motion). Lattice units.
module dkt_lubrication
  use dkt_kinds, only: wp, pi
  implicit none
  private
  public :: lubrication_t, lubrication_add_pair, lubrication_add_walls

  !> The correction's parameters (lattice units); on = .false. leaves every sum untouched.
  type :: lubrication_t
    logical :: on = .false.
    real(wp) :: mu = 0       !! dynamic viscosity rho_f nu
    real(wp) :: cutoff = 1   !! h_c: the gap from which the lattice resolves the film
    real(wp) :: hmin = 0.01  !! h_min: the smallest gap the theory is taken at
  end type lubrication_t

contains

  !> C(h) for the reduced radius astar (0 at h >= cutoff).
  pure real(wp) function coefficient(lub, astar, h) result(c)
    type(lubrication_t), intent(in) :: lub
    real(wp), intent(in) :: astar, h
    real(wp) :: g
    c = 0.0_wp
    if (.not. (h < lub%cutoff)) return
    g = max(h, lub%hmin)
    c = 3.0_wp*sqrt(2.0_wp)*pi*lub%mu*astar*sqrt(astar)* &
        (1.0_wp/(g*sqrt(g)) - 1.0_wp/(lub%cutoff*sqrt(lub%cutoff)))
  end function coefficient

  !> Add the film between disk (x, y, r) and a partner (xb, yb, rb) moving at (ub, vb) to the
  !! implicit system of the disk's velocity U: a = a + C n n^T, b = b + C (U_b . n) n, so that
  !! (M I + h a) U_new = M U + h (F + b) holds the force -C ((U_new - U_b) . n) n.
  pure subroutine lubrication_add_pair(lub, x, y, r, xb, yb, rb, ub, vb, a, b)
    type(lubrication_t), intent(in) :: lub
    real(wp), intent(in) :: x, y, r, xb, yb, rb, ub, vb
    real(wp), intent(inout) :: a(3), b(2) !! a: the symmetric matrix as (11, 12, 22)
    real(wp) :: d, nx, ny, c
    d = sqrt((x - xb)**2 + (y - yb)**2)
    if (.not. (d - r - rb < lub%cutoff) .or. d <= 0.0_wp) return
    c = coefficient(lub, r*rb/(r + rb), d - r - rb)
    nx = (x - xb)/d
    ny = (y - yb)/d
    call add(c, nx, ny, ub*nx + vb*ny, a, b)
  end subroutine lubrication_add_pair

  !> Add the film between disk (x, y, r) and each wall taken (the sides x = 0, x = width, the
  !! ends y = 0, y = height; walls at rest): a* = r, n the wall's normal into the channel.
  pure subroutine lubrication_add_walls(lub, x, y, r, width, height, walls, a, b)
    type(lubrication_t), intent(in) :: lub
    real(wp), intent(in) :: x, y, r, width, height
    logical, intent(in) :: walls(4)
    real(wp), intent(inout) :: a(3), b(2)
    if (walls(1)) call add(coefficient(lub, r, x - r), 1.0_wp, 0.0_wp, 0.0_wp, a, b)
    if (walls(2)) call add(coefficient(lub, r, width - x - r), -1.0_wp, 0.0_wp, 0.0_wp, a, b)
    if (walls(3)) call add(coefficient(lub, r, y - r), 0.0_wp, 1.0_wp, 0.0_wp, a, b)
    if (walls(4)) call add(coefficient(lub, r, height - y - r), 0.0_wp, -1.0_wp, 0.0_wp, a, b)
  end subroutine lubrication_add_walls

  !> a += c n n^T, b += c vn n
  pure subroutine add(c, nx, ny, vn, a, b)
    real(wp), intent(in) :: c, nx, ny, vn
    real(wp), intent(inout) :: a(3), b(2)
    if (c == 0.0_wp) return
    a = a + c*[nx*nx, nx*ny, ny*ny]
    b = b + c*vn*[nx, ny]
  end subroutine add

end module dkt_lubrication

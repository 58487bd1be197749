!> Short-range repulsive forces between particles and against walls (Wan & Turek 2006;
!> docs/model.md E10–E11). They keep resolved particles from overlapping where the lattice can no
!> longer resolve the lubrication film. Lattice units; a pair further apart than the sum of the
!> radii plus the range costs one distance test.
module dkt_collisions
  use dkt_kinds, only: wp
  implicit none
  private
  public :: collision_forces, repel

contains

  !> E10 between every pair and E11 against the mirror images across the side walls x = 0 and
  !! x = width (and the ends y = 0 and y = height when they are walls).
  pure subroutine collision_forces(x, y, r, width, height, walls_y, eps, eps_overlap, range, &
                                   cx, cy)
    real(wp), intent(in) :: x(:), y(:), r(:)    !! centres and radii
    real(wp), intent(in) :: width, height       !! channel size
    logical, intent(in) :: walls_y              !! the ends are walls
    real(wp), intent(in) :: eps, eps_overlap    !! eps_p and eps'_p of E10
    real(wp), intent(in) :: range               !! threshold xi of E10
    real(wp), intent(out) :: cx(:), cy(:)       !! force on each particle
    integer :: a, b, m
    real(wp) :: fx, fy, mx, my
    cx = 0.0_wp
    cy = 0.0_wp
    do a = 1, size(x)
      do b = a + 1, size(x)
        call repel(x(a), y(a), x(b), y(b), r(a) + r(b), eps, eps_overlap, range, fx, fy)
        cx(a) = cx(a) + fx
        cy(a) = cy(a) + fy
        cx(b) = cx(b) - fx
        cy(b) = cy(b) - fy
      end do
      ! E11: the mirror particle X' across each wall, 2 R in place of R_i + R_j, stiffness
      ! halved
      do m = 1, merge(4, 2, walls_y)
        select case (m)
        case (1); mx = -x(a); my = y(a)
        case (2); mx = 2.0_wp*width - x(a); my = y(a)
        case (3); mx = x(a); my = -y(a)
        case default; mx = x(a); my = 2.0_wp*height - y(a)
        end select
        call repel(x(a), y(a), mx, my, 2.0_wp*r(a), 0.5_wp*eps, 0.5_wp*eps_overlap, range, &
                   fx, fy)
        cx(a) = cx(a) + fx
        cy(a) = cy(a) + fy
      end do
    end do
  end subroutine collision_forces

  !> E10 on the first of two disks whose radii add to rsum: zero beyond rsum + range, growing
  !! with the square of the gap inside the range, linear in the overlap.
  pure subroutine repel(xa, ya, xb, yb, rsum, eps, eps_overlap, range, fx, fy)
    real(wp), intent(in) :: xa, ya, xb, yb, rsum, eps, eps_overlap, range
    real(wp), intent(out) :: fx, fy
    real(wp) :: d, c
    d = sqrt((xa - xb)**2 + (ya - yb)**2)
    if (d > rsum + range) then
      c = 0.0_wp
    else if (d >= rsum) then
      c = (rsum + range - d)**2/eps
    else
      c = (rsum - d)/eps_overlap
    end if
    fx = (xa - xb)*c
    fy = (ya - yb)*c
  end subroutine repel

end module dkt_collisions

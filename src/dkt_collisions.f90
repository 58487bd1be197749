!> Short-range repulsive forces between particles and against walls (Wan & Turek 2006;
!> docs/model.md E10–E11). They keep resolved particles from overlapping where the lattice can no
!> longer resolve the lubrication film. Lattice units; a pair further apart than the sum of the
!> radii plus the range costs one distance test.
module dkt_collisions
  use dkt_kinds, only: wp
  implicit none
  private
  public :: collision_forces, collision_force_on, repel

contains

  !> E10 between every pair and E11 against the mirror images across the side walls x = 0 and
  !! x = width, and across each end y = 0, y = height that is a wall (an end at rest).
  pure subroutine collision_forces(x, y, r, width, height, end_walls, eps, eps_overlap, range, &
                                   cx, cy)
    real(wp), intent(in) :: x(:), y(:), r(:)    !! centres and radii
    real(wp), intent(in) :: width, height       !! channel size
    logical, intent(in) :: end_walls(2)         !! the lower, the upper end is a wall
    real(wp), intent(in) :: eps, eps_overlap    !! eps_p and eps'_p of E10
    real(wp), intent(in) :: range               !! threshold xi of E10
    real(wp), intent(out) :: cx(:), cy(:)       !! force on each particle
    integer :: a, b
    real(wp) :: fx, fy
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
      call add_wall_forces(x(a), y(a), r(a), width, height, end_walls, eps, eps_overlap, &
                           range, cx(a), cy(a))
    end do
  end subroutine collision_forces

  !> The contact force (fx, fy) on particle k alone: cx(k), cy(k) of collision_forces with the
  !! same arguments, summed in the same order (the pairs (a, k) for a < k, then (k, b) for b > k,
  !! then the walls), so with the same bits, in time linear in the number of particles.
  !! With near (ascending indices; k may be among them), only the pairs of k with the particles
  !! listed are summed, in the same order: the same bits when near holds every particle within
  !! the range of k, because a pair beyond the range adds a zero to a sum that starts at +0 and
  !! so is never -0 (in round-to-nearest x + (+-0) = x for x /= -0).
  pure subroutine collision_force_on(k, x, y, r, width, height, end_walls, eps, eps_overlap, &
                                     range, fx, fy, near)
    integer, intent(in) :: k                    !! the particle
    real(wp), intent(in) :: x(:), y(:), r(:)    !! centres and radii
    real(wp), intent(in) :: width, height       !! channel size
    logical, intent(in) :: end_walls(2)         !! the lower, the upper end is a wall
    real(wp), intent(in) :: eps, eps_overlap    !! eps_p and eps'_p of E10
    real(wp), intent(in) :: range               !! threshold xi of E10
    real(wp), intent(out) :: fx, fy             !! force on particle k
    integer, intent(in), optional :: near(:)    !! the candidates, ascending (default: all)
    integer :: a, m
    fx = 0.0_wp
    fy = 0.0_wp
    if (present(near)) then
      do m = 1, size(near)
        call add_pair(near(m), fx, fy)
      end do
    else
      do a = 1, size(x)
        call add_pair(a, fx, fy)
      end do
    end if
    call add_wall_forces(x(k), y(k), r(k), width, height, end_walls, eps, eps_overlap, range, &
                         fx, fy)
  contains
    !> The force of particle a on k, with the arguments of repel in the order collision_forces
    !! gives them (the lower index first).
    pure subroutine add_pair(a, fx, fy)
      integer, intent(in) :: a
      real(wp), intent(inout) :: fx, fy
      real(wp) :: gx, gy
      if (a < k) then
        call repel(x(a), y(a), x(k), y(k), r(a) + r(k), eps, eps_overlap, range, gx, gy)
        fx = fx - gx
        fy = fy - gy
      else if (a > k) then
        call repel(x(k), y(k), x(a), y(a), r(k) + r(a), eps, eps_overlap, range, gx, gy)
        fx = fx + gx
        fy = fy + gy
      end if
    end subroutine add_pair
  end subroutine collision_force_on

  !> Add to (fx, fy) the force of each wall on the disk at (x, y) of radius r, one wall after
  !! the other (E11: the mirror disk, half the stiffness): the sides, then the lower end and the
  !! upper end, each only when it is a wall. The order of the sums is the same whichever ends
  !! are walls, so a scene with both ends walls keeps its bits.
  pure subroutine add_wall_forces(x, y, r, width, height, end_walls, eps, eps_overlap, range, &
                                  fx, fy)
    real(wp), intent(in) :: x, y, r, width, height, eps, eps_overlap, range
    logical, intent(in) :: end_walls(2) !! the lower, the upper end is a wall
    real(wp), intent(inout) :: fx, fy
    real(wp) :: gx, gy, mx, my
    integer :: m
    do m = 1, 4
      select case (m)
      case (1); mx = -x; my = y
      case (2); mx = 2.0_wp*width - x; my = y
      case (3)
        if (.not. end_walls(1)) cycle
        mx = x; my = -y
      case default
        if (.not. end_walls(2)) cycle
        mx = x; my = 2.0_wp*height - y
      end select
      call repel(x, y, mx, my, 2.0_wp*r, 0.5_wp*eps, 0.5_wp*eps_overlap, range, gx, gy)
      fx = fx + gx
      fy = fy + gy
    end do
  end subroutine add_wall_forces

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

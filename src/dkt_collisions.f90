!> Short-range repulsive forces between particles and against walls (Wan & Turek 2006;
!> docs/model.md E10–E11). They keep resolved particles from overlapping where the lattice can no
!> longer resolve the lubrication film. Lattice units; a pair further apart than the sum of the
!> radii plus the range costs one distance test.
module dkt_collisions
  use, intrinsic :: ieee_arithmetic, only: ieee_is_finite
  use dkt_kinds, only: wp
  use dkt_cells, only: sort_ascending
  implicit none
  private
  public :: collision_forces, collision_force_on, collision_partners, repel, &
            collision_stable_substeps

  !> The largest |coordinate| of a centre that collision_partners may leave out of a list.
  real(wp), parameter :: FAR = 1.0e100_wp

contains

  !> The fewest particle sub-steps per fluid step for which the explicit update (E8) of the
  !! stiffest contact (E10–E11) stays stable: omega h <= 1, with omega^2 = k / m for the
  !! spring constant k of the overlap or range law at contact and the reduced mass m, over the
  !! disks of radii r, masses mass, free or not. Disks of one kind (radius, mass, free or not)
  !! give the same springs, so the pairs are taken between kinds: linear in the disks for a
  !! scene of a few kinds, and the same value as over all pairs. huge(n) stands for a count too
  !! large for an integer.
  pure integer function collision_stable_substeps(r, mass, free, eps, eps_overlap, range) result(n)
    real(wp), intent(in) :: r(:), mass(:)
    logical, intent(in) :: free(:)
    real(wp), intent(in) :: eps, eps_overlap !! eps_p and eps'_p of E10
    real(wp), intent(in) :: range            !! threshold xi of E10
    real(wp) :: omega, k, m
    integer :: a, b, i, j, nk
    integer, allocatable :: first(:), members(:) !! a disk of each kind, how many there are
    allocate (first(size(r)), members(size(r)))
    nk = 0
    do a = 1, size(r)
      do j = 1, nk
        b = first(j)
        if (r(b) == r(a) .and. mass(b) == mass(a) .and. (free(b) .eqv. free(a))) exit
      end do
      if (j > nk) then
        nk = j
        first(j) = a
        members(j) = 0
      end if
      members(j) = members(j) + 1
    end do
    omega = 0.0_wp
    do i = 1, nk
      a = first(i)
      if (.not. free(a)) cycle
      ! the wall: the mirror disk at d = 2 r, stiffness halved (E11)
      k = spring(2.0_wp*r(a), 0.5_wp*eps, 0.5_wp*eps_overlap)
      omega = max(omega, sqrt(k/mass(a)))
      do j = 1, nk
        if (j == i .and. members(i) < 2) cycle ! no other disk of this kind
        b = first(j)
        k = spring(r(a) + r(b), eps, eps_overlap)
        m = mass(a)
        if (free(b)) m = m*mass(b)/(m + mass(b))
        omega = max(omega, sqrt(k/m))
      end do
    end do
    if (omega >= real(huge(n), wp)) then
      n = huge(n)
    else
      n = max(1, ceiling(omega))
    end if
  contains
    !> dF/dgap of E10 at contact: d/eps' in the overlap, up to 2 d xi/eps in the range
    pure real(wp) function spring(d, eps_d, eps_overlap_d)
      real(wp), intent(in) :: d, eps_d, eps_overlap_d
      spring = max(d/eps_overlap_d, 2.0_wp*d*range/eps_d)
    end function spring
  end function collision_stable_substeps

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
      call add_wall_forces(x(a), y(a), r(a), width, height, [.true., .true., end_walls], eps, &
                           eps_overlap, range, cx(a), cy(a))
    end do
  end subroutine collision_forces

  !> The contact force (fx, fy) on particle k alone: cx(k), cy(k) of collision_forces with the
  !! same arguments, summed in the same order (the pairs (a, k) for a < k, then (k, b) for b > k,
  !! then the walls), so with the same bits, in time linear in the number of particles.
  !! With near (ascending indices; k may be among them), only the pairs of k with the particles
  !! listed are summed, in the same order: the same bits when near holds every particle within
  !! the range of k, because a pair beyond the range adds a zero to a sum that starts at +0 and
  !! so is never -0 (in round-to-nearest x + (+-0) = x for x /= -0). With walls, only the walls
  !! it names are taken, in the same order: the same bits when each wall left out is beyond the
  !! range of k (collision_partners finds both lists).
  pure subroutine collision_force_on(k, x, y, r, width, height, end_walls, eps, eps_overlap, &
                                     range, fx, fy, near, walls)
    integer, intent(in) :: k                    !! the particle
    real(wp), intent(in) :: x(:), y(:), r(:)    !! centres and radii
    real(wp), intent(in) :: width, height       !! channel size
    logical, intent(in) :: end_walls(2)         !! the lower, the upper end is a wall
    real(wp), intent(in) :: eps, eps_overlap    !! eps_p and eps'_p of E10
    real(wp), intent(in) :: range               !! threshold xi of E10
    real(wp), intent(out) :: fx, fy             !! force on particle k
    integer, intent(in), optional :: near(:)    !! the candidates, ascending (default: all)
    !> the walls to take: the sides x = 0, x = width, the ends y = 0, y = height (default: the
    !! sides and the ends that are walls)
    logical, intent(in), optional :: walls(4)
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
    if (present(walls)) then
      call add_wall_forces(x(k), y(k), r(k), width, height, walls, eps, eps_overlap, range, &
                           fx, fy)
    else
      call add_wall_forces(x(k), y(k), r(k), width, height, [.true., .true., end_walls], eps, &
                           eps_overlap, range, fx, fy)
    end if
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
  !! upper end, each only when it is taken (an end only when it is a wall). The order of the sums
  !! is the same whichever walls are taken, so a scene with both ends walls keeps its bits.
  pure subroutine add_wall_forces(x, y, r, width, height, walls, eps, eps_overlap, range, fx, fy)
    real(wp), intent(in) :: x, y, r, width, height, eps, eps_overlap, range
    logical, intent(in) :: walls(4) !! take the side x = 0, x = width, the end y = 0, y = height
    real(wp), intent(inout) :: fx, fy
    real(wp) :: gx, gy, mx, my
    integer :: m
    do m = 1, 4
      if (.not. walls(m)) cycle
      select case (m)
      case (1); mx = -x; my = y
      case (2); mx = 2.0_wp*width - x; my = y
      case (3); mx = x; my = -y
      case default; mx = x; my = 2.0_wp*height - y
      end select
      ! a wall beyond the range adds an exact zero (apart): most disks are far from every wall
      if (apart(x - mx, y - my, 2.0_wp*r + range)) cycle
      call repel(x, y, mx, my, 2.0_wp*r, 0.5_wp*eps, 0.5_wp*eps_overlap, range, gx, gy)
      fx = fx + gx
      fy = fy + gy
    end do
  end subroutine add_wall_forces

  !> Whether repel gives an exact zero force (+-0 in each component) for two centres dx, dy
  !! apart (x_a - x_b, y_a - y_b as repel takes them) whose radii and range add to lim
  !! (rsum + range, as repel adds them): true when dx and dy are finite and one of them is
  !! beyond lim (and not so small that its square underflows). The rounded square root of a
  !! rounded square is the number itself, and adding a square only makes the sum larger, so
  !! the distance of repel is then beyond lim too: c = 0 and (dx c, dy c) = +-0. Added to a
  !! sum that starts at +0, +-0 changes no bit: the sum is never -0 (in round-to-nearest
  !! x + y = -0 only for x = y = -0), and x + (+-0) = x for every other x.
  pure logical function apart(dx, dy, lim)
    real(wp), intent(in) :: dx, dy, lim
    real(wp) :: far
    apart = .false.
    ! (finite first: an ordered comparison with NaN traps in the checked build)
    if (.not. (ieee_is_finite(dx) .and. ieee_is_finite(dy) .and. ieee_is_finite(lim))) return
    far = max(abs(dx), abs(dy))
    apart = far > lim .and. far > 1.0e-100_wp
  end function apart

  !> The partners of particle k among its candidates near (cells_near's, in any order) that may
  !! push it (E10) while its centre stays within drift of (x(k), y(k)), the others where they
  !! are: part(1:np), ascending; and the walls that may (walls, as collision_force_on takes them).
  !! A candidate left out is one whose centre is finite, within FAR of the origin as the centre
  !! of k is, and farther from (x(k), y(k)) than the sum of the radii plus the range plus drift,
  !! with a relative margin far above rounding; a wall left out is one whose mirror disk is as
  !! far. Its force on k at any centre within drift is then an exact zero (apart), which adds
  !! nothing to the sum of collision_force_on. So collision_force_on with part and walls has
  !! the bits of that with every candidate in ascending order and every wall, for every centre
  !! of k within drift of the start; k itself is left out too (it adds nothing).
  pure subroutine collision_partners(k, x, y, r, width, height, end_walls, range, drift, near, &
                                     part, np, walls)
    integer, intent(in) :: k                    !! the particle
    real(wp), intent(in) :: x(:), y(:), r(:)    !! centres (of k: at the start) and radii
    real(wp), intent(in) :: width, height       !! channel size
    logical, intent(in) :: end_walls(2)         !! the lower, the upper end is a wall
    real(wp), intent(in) :: range               !! threshold xi of E10
    real(wp), intent(in) :: drift               !! the farthest k moves from (x(k), y(k))
    integer, intent(in) :: near(:)              !! the candidates
    integer, allocatable, intent(inout) :: part(:) !! grown as needed
    integer, intent(out) :: np
    logical, intent(out) :: walls(4)            !! the walls that may push k
    integer :: l, a
    real(wp) :: t, margin
    if (allocated(part)) then
      if (size(part) < size(near)) deallocate (part)
    end if
    if (.not. allocated(part)) allocate (part(max(64, 2*size(near))))
    np = 0
    walls = [.true., .true., end_walls]
    if (placed(x(k), y(k)) .and. ieee_is_finite(drift)) then
      ! the distances from the centre to its mirror disks across the walls
      t = (2.0_wp*r(k) + range + 2.0_wp*drift)*(1.0_wp + 1.0e-9_wp)
      if (ieee_is_finite(t) .and. ieee_is_finite(width) .and. ieee_is_finite(height)) then
        if (t >= 0.0_wp .and. abs(width) <= FAR .and. abs(height) <= FAR) then
          margin = t + 1.0e-9_wp*(abs(x(k)) + abs(y(k)) + abs(width) + abs(height)) + 1.0e-90_wp
          walls = walls .and. [2.0_wp*abs(x(k)), 2.0_wp*abs(width - x(k)), 2.0_wp*abs(y(k)), &
                               2.0_wp*abs(height - y(k))] <= margin
        end if
      end if
      do l = 1, size(near)
        a = near(l)
        if (a == k) cycle
        if (placed(x(a), y(a))) then
          if (beyond(a)) cycle
        end if
        np = np + 1
        part(np) = a
      end do
    else
      ! every candidate but k itself
      do l = 1, size(near)
        if (near(l) == k) cycle
        np = np + 1
        part(np) = near(l)
      end do
    end if
    ! ascending (the partners are few)
    call sort_ascending(part, np)
  contains
    !> Whether a centre is finite and within FAR of the origin.
    pure logical function placed(px, py)
      real(wp), intent(in) :: px, py
      placed = ieee_is_finite(px) .and. ieee_is_finite(py)
      if (placed) placed = abs(px) <= FAR .and. abs(py) <= FAR
    end function placed
    !> Whether the centre of a (placed) lies beyond the reach of k's: the distance squared
    !! beyond that of (rsum + range + drift) (1 + 1e-9), rsum + range summed as repel sums them.
    pure logical function beyond(a)
      integer, intent(in) :: a
      real(wp) :: t
      beyond = .false.
      t = ((r(a) + r(k)) + range + drift)*(1.0_wp + 1.0e-9_wp)
      if (.not. ieee_is_finite(t)) return
      if (t < 0.0_wp .or. t > FAR) return
      beyond = (x(a) - x(k))**2 + (y(a) - y(k))**2 > t*t
    end function beyond
  end subroutine collision_partners

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

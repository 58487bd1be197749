!> Unit tests of the Wan–Turek repulsion (docs/model.md E10–E11):
!>  - no force beyond R_i + R_j + xi; equal and opposite forces along the line of centres;
!>  - inside the range the force is (X_i - X_j)(R_i + R_j + xi - d)^2/eps_p;
!>  - overlapping disks: (X_i - X_j)(R_i + R_j - d)/eps'_p;
!>  - a wall acts as the mirror particle with half the stiffness (E11): the range test is on
!>    d' - 2R, twice the gap to the wall.
!>  - each end is a wall on its own: a disk near the lower end is pushed up when only the lower
!>    end is a wall, not when only the upper one is, and the reverse near the upper end; in a
!>    box that holds the disk between both ends the two pushes cancel.
!>  - the wall forces add up in one order, the sides, the lower end, the upper end, whichever
!>    ends are walls (a scene with both ends walls keeps its bits).
!>  - collision_force_on(k) gives particle k's force of collision_forces with the same bits, in a
!>    crowd of disks some touching, some overlapping, some near the walls, for each choice of
!>    end walls.
!>  - the cell list (dkt_cells) finds every contact partner: collision_force_on over the disks
!>    cells_near returns has the bits of the sum over all disks, for a random crowd of disks of
!>    radius 1..2 with pairs of the largest disks placed exactly at, just inside and just
!>    beyond R_i + R_j + xi (the reach of a query: a shorter reach loses them), and for a crowd
!>    with a disk at NaN and one at 1e200 (the sum over all is NaN there: so must it be); and
!>    the cells do prune (most queries return a small part of the crowd).
program test_collisions
  use dkt_kinds, only: wp
  use dkt_check, only: check, finish
  use, intrinsic :: ieee_arithmetic, only: ieee_value, ieee_quiet_nan
  use, intrinsic :: ieee_exceptions, only: ieee_invalid, ieee_overflow, ieee_set_flag
  use, intrinsic :: ieee_exceptions, only: ieee_get_halting_mode, ieee_set_halting_mode
  use dkt_collisions, only: collision_forces, collision_force_on, repel
  use dkt_cells, only: cells_t, cells_build, cells_near
  implicit none
  real(wp) :: cx(2), cy(2), x(2), y(2), r(2)
  real(wp), parameter :: eps = 2.0_wp, eps_ov = 0.5_wp, xi = 1.0_wp, big = 1.0e6_wp
  !> the lower and upper end walls: both, neither, the lower only, the upper only
  logical, parameter :: CLOSED(2) = [.true., .true.], NEITHER(2) = [.false., .false.], &
                        LOWER(2) = [.true., .false.], UPPER(2) = [.false., .true.]

  r = [5.0_wp, 3.0_wp]
  ! far apart, far from the walls (width and height huge)
  x = [100.0_wp, 109.5_wp]
  y = [200.0_wp, 200.0_wp]
  call collision_forces(x, y, r, big, big, CLOSED, eps, eps_ov, xi, cx, cy)
  call check('no force beyond R1 + R2 + xi', all([cx, cy] == 0.0_wp), maxval(abs([cx, cy])))

  ! gap 0.4 inside the range along x: |F| = d (xi - gap)^2 / eps
  x = [100.0_wp, 108.4_wp]
  call collision_forces(x, y, r, big, big, CLOSED, eps, eps_ov, xi, cx, cy)
  call check('range force (X1 - X2)(R1 + R2 + xi - d)^2/eps_p', &
             abs(cx(1) - (-8.4_wp*0.6_wp**2/eps)) < 1.0e-12_wp, cx(1))
  call check('equal and opposite, along the line of centres', &
             cx(1) == -cx(2) .and. all(cy == 0.0_wp), cx(1) + cx(2))

  ! overlap 0.5: |F| = d (R1 + R2 - d)/eps'
  x = [100.0_wp, 107.5_wp]
  call collision_forces(x, y, r, big, big, CLOSED, eps, eps_ov, xi, cx, cy)
  call check('overlap force (X1 - X2)(R1 + R2 - d)/eps''_p', &
             abs(cx(1) - (-7.5_wp*0.5_wp/eps_ov)) < 1.0e-12_wp, cx(1))

  ! a disk 5.3 from the left wall: mirror at -5.3, d' = 10.6, 2R = 10, so d' - 2R = 0.6 (twice
  ! the gap to the wall) is inside the range
  call collision_forces([5.3_wp], [200.0_wp], [5.0_wp], big, big, CLOSED, eps, eps_ov, xi, &
                        cx(1:1), cy(1:1))
  call check('wall: mirror particle with half the stiffness (E11)', &
             abs(cx(1) - 10.6_wp*0.4_wp**2/(0.5_wp*eps)) < 1.0e-12_wp, cx(1))
  ! 5.5 from the wall: d' - 2R = 1 = xi, the edge of the range
  call collision_forces([5.5_wp], [200.0_wp], [5.0_wp], big, big, CLOSED, eps, eps_ov, xi, &
                        cx(1:1), cy(1:1))
  call check('wall: no force once d'' - 2R reaches xi', cx(1) == 0.0_wp, cx(1))
  ! the same disk near the bottom end: felt only when the ends are walls
  call collision_forces([200.0_wp], [5.3_wp], [5.0_wp], big, big, NEITHER, eps, eps_ov, xi, &
                        cx(1:1), cy(1:1))
  call check('open ends exert no wall force', cy(1) == 0.0_wp, cy(1))
  call collision_forces([200.0_wp], [5.3_wp], [5.0_wp], big, big, CLOSED, eps, eps_ov, xi, &
                        cx(1:1), cy(1:1))
  call check('closed ends push the disk back', cy(1) > 0.0_wp, cy(1))

  call each_end_alone()
  call wall_order()
  call one_particle_same_bits(CLOSED)
  call one_particle_same_bits(NEITHER)
  call one_particle_same_bits(LOWER)
  call one_particle_same_bits(UPPER)
  call cells_same_bits(.false.)
  call cells_same_bits(.true.)

  call finish()

contains

  !> A disk of radius 5 with its surface 0.3 from an end (inside the range xi = 1) in a 400 x 40
  !! box, near the lower end (y = 5.3) and near the upper end (y = 34.7); then in a box of
  !! height 10.6 that holds it 0.3 from both ends.
  subroutine each_end_alone()
    real(wp) :: lo(4), hi(4), both(4), fx(1)
    logical :: ends(2, 4)
    integer :: j
    ends = reshape([CLOSED, NEITHER, LOWER, UPPER], [2, 4])
    do j = 1, 4
      call collision_forces([200.0_wp], [5.3_wp], [5.0_wp], 400.0_wp, 40.0_wp, ends(:, j), &
                            eps, eps_ov, xi, fx, lo(j:j))
      call collision_forces([200.0_wp], [34.7_wp], [5.0_wp], 400.0_wp, 40.0_wp, ends(:, j), &
                            eps, eps_ov, xi, fx, hi(j:j))
      call collision_forces([200.0_wp], [5.3_wp], [5.0_wp], 400.0_wp, 10.6_wp, ends(:, j), &
                            eps, eps_ov, xi, fx, both(j:j))
    end do
    call check('lower end alone a wall: pushes a disk near it up (E11)', &
               abs(lo(3) - 10.6_wp*0.4_wp**2/(0.5_wp*eps)) < 1.0e-12_wp, lo(3))
    call check('lower end alone a wall: the bits of both ends walls', lo(3) == lo(1), lo(3) - lo(1))
    call check('lower end alone a wall: no force near the upper end', hi(3) == 0.0_wp, hi(3))
    call check('upper end alone a wall: pushes a disk near it down (E11)', &
               abs(hi(4) + 10.6_wp*0.4_wp**2/(0.5_wp*eps)) < 1.0e-9_wp, hi(4))
    call check('upper end alone a wall: the bits of both ends walls', hi(4) == hi(1), hi(4) - hi(1))
    call check('upper end alone a wall: no force near the lower end', lo(4) == 0.0_wp, lo(4))
    call check('no end a wall: no force near either end', lo(2) == 0.0_wp .and. hi(2) == 0.0_wp, &
               max(abs(lo(2)), abs(hi(2))))
    call check('between two end walls the pushes cancel', abs(both(1)) < 1.0e-9_wp, both(1))
    call check('between two ends, the lower alone pushes up', both(3) > 1.0_wp, both(3))
    call check('between two ends, the upper alone pushes down', both(4) < -1.0_wp, both(4))
  end subroutine each_end_alone

  !> A disk in the corner of a 10.6 x 10.7 box, within the range of all four walls: its force is
  !! the sum of the mirror forces (repel, half the stiffness) in the order left, right, lower,
  !! upper, with the same bits, for every choice of end walls.
  subroutine wall_order()
    real(wp), parameter :: px = 5.2_wp, py = 5.4_wp, pr = 5.0_wp, w = 10.6_wp, h = 10.7_wp
    real(wp) :: fx(1), fy(1), ex, ey, gx(4), gy(4)
    logical :: ends(2, 4)
    integer :: j, bad
    ends = reshape([CLOSED, NEITHER, LOWER, UPPER], [2, 4])
    call repel(px, py, -px, py, 2*pr, 0.5_wp*eps, 0.5_wp*eps_ov, xi, gx(1), gy(1))
    call repel(px, py, 2*w - px, py, 2*pr, 0.5_wp*eps, 0.5_wp*eps_ov, xi, gx(2), gy(2))
    call repel(px, py, px, -py, 2*pr, 0.5_wp*eps, 0.5_wp*eps_ov, xi, gx(3), gy(3))
    call repel(px, py, px, 2*h - py, 2*pr, 0.5_wp*eps, 0.5_wp*eps_ov, xi, gx(4), gy(4))
    bad = 0
    do j = 1, 4
      ex = 0.0_wp + gx(1) + gx(2)
      ey = 0.0_wp + gy(1) + gy(2)
      if (ends(1, j)) ex = ex + gx(3)
      if (ends(1, j)) ey = ey + gy(3)
      if (ends(2, j)) ex = ex + gx(4)
      if (ends(2, j)) ey = ey + gy(4)
      call collision_forces([px], [py], [pr], w, h, ends(:, j), eps, eps_ov, xi, fx, fy)
      if (fx(1) /= ex .or. fy(1) /= ey) bad = bad + 1
    end do
    call check('the walls add up as left, right, lower, upper', bad == 0, real(bad, wp))
    call check('the corner disk feels every wall', all(gy(3:4) /= 0.0_wp) .and. &
               all(gx(1:2) /= 0.0_wp), minval(abs([gx(1:2), gy(3:4)])))
  end subroutine wall_order

  !> 60 disks of radius 2..3 dropped at random into a 40 x 40 box: many within the range or
  !! overlapping each other or a wall; every particle's force alone equals the crowd's.
  subroutine one_particle_same_bits(ends)
    logical, intent(in) :: ends(2) !! the lower, the upper end is a wall
    integer, parameter :: n = 60
    real(wp) :: px(n), py(n), pr(n), fx(n), fy(n), gx, gy
    integer :: k, bad
    call random_seed()
    call random_crowd(40.0_wp, 2.0_wp, px, py, pr)
    call collision_forces(px, py, pr, 40.0_wp, 40.0_wp, ends, eps, eps_ov, xi, fx, fy)
    bad = 0
    do k = 1, n
      call collision_force_on(k, px, py, pr, 40.0_wp, 40.0_wp, ends, eps, eps_ov, xi, gx, gy)
      if (gx /= fx(k) .or. gy /= fy(k)) bad = bad + 1
    end do
    call check('one particle''s force has the bits of collision_forces', bad == 0, real(bad, wp))
    call check('the crowd is in contact', count(fx /= 0.0_wp) > n/2, real(count(fx /= 0.0_wp), wp))
  end subroutine one_particle_same_bits

  !> 600 disks of radius 1..2 at random in a 200 x 200 box, one at the origin (so the cells,
  !! of side 2 R_max + xi = 5, start there), and 30 pairs of disks of radius 2 set along x, y
  !! and the diagonal (3, 4) at exactly R_i + R_j + xi = 5, 2^-40 inside and 2^-40 beyond it
  !! (distances exact in binary); the first disk of a pair sits 2^-14 from a cell's edge, so
  !! that its partner lies in the next cell, which a query whose reach falls short by more than
  !! that misses. With strays, disk 7 at NaN and disk 8 at y = 1e200. Every disk's force from
  !! the disks its cells list equals, bit for bit, the force from all disks.
  subroutine cells_same_bits(strays)
    logical, intent(in) :: strays
    integer, parameter :: n = 600
    real(wp), parameter :: delta = 2.0_wp**(-40)
    real(wp) :: px(n), py(n), pr(n), fx, fy, gx, gy, rmax, gap
    type(cells_t) :: c
    integer, allocatable :: near(:)
    integer :: k, m, bad, few, at_edge, j, nan_forces
    logical :: halt(2)
    call random_crowd(200.0_wp, 1.0_wp, px, py, pr)
    pr(1:60) = 2.0_wp
    px(n) = 0.0_wp
    py(n) = 0.0_wp
    do j = 1, 60, 2
      ! each pair at a site of its own, 20 apart: two pairs snapped to one site could cancel
      ! a disk's force exactly (it happened about once in 100 random crowds)
      px(j) = 5.0_wp*(2 + 4*mod((j - 1)/2, 8)) + 2.0_wp**(-14)
      py(j) = 5.0_wp*(2 + 4*((j - 1)/16)) - 2.0_wp**(-14)
      gap = 0.0_wp
      if (mod(j/2, 3) == 1) gap = -delta ! inside the range
      if (mod(j/2, 3) == 2) gap = delta  ! beyond it
      select case (mod(j/6, 3))
      case (0); px(j + 1) = px(j) + 5.0_wp + gap; py(j + 1) = py(j)
      case (1); px(j + 1) = px(j); py(j + 1) = py(j) - 5.0_wp - gap
      case default; px(j + 1) = px(j) + 3.0_wp; py(j + 1) = py(j) + 4.0_wp + gap
      end select
    end do
    if (strays) then
      px(7) = ieee_value(px(7), ieee_quiet_nan)
      py(8) = 1.0e200_wp
      ! the NaN and the overflow are the point here: no trap (debug builds trap both)
      call ieee_get_halting_mode([ieee_invalid, ieee_overflow], halt)
      call ieee_set_halting_mode([ieee_invalid, ieee_overflow], .false.)
    end if
    rmax = maxval(pr)
    call cells_build(c, px, py, 2.0_wp*rmax + xi)
    bad = 0
    few = 0
    at_edge = 0
    nan_forces = 0
    do k = 1, n
      call cells_near(c, px(k), py(k), pr(k) + rmax + xi, near, m)
      if (m < n/10) few = few + 1
      call collision_force_on(k, px, py, pr, 200.0_wp, 200.0_wp, CLOSED, eps, eps_ov, xi, gx, gy)
      call collision_force_on(k, px, py, pr, 200.0_wp, 200.0_wp, CLOSED, eps, eps_ov, xi, fx, &
                              fy, near(1:m))
      if (gx /= gx) nan_forces = nan_forces + 1
      if (transfer(fx, 1_8) /= transfer(gx, 1_8) .or. transfer(fy, 1_8) /= transfer(gy, 1_8)) &
        bad = bad + 1
      if (k <= 60 .and. mod((k - 1)/2, 3) == 1 .and. (gx /= 0.0_wp .or. gy /= 0.0_wp)) &
        at_edge = at_edge + 1
    end do
    if (strays) then
      call ieee_set_flag([ieee_invalid, ieee_overflow], .false.)
      call ieee_set_halting_mode([ieee_invalid, ieee_overflow], halt)
    end if
    call check('cells: every disk''s contact force has the bits of the sum over all disks', &
               bad == 0, real(bad, wp))
    call check('cells: a query returns a small part of the crowd', few > n/2, real(few, wp))
    if (strays) then
      call check('cells: a disk at NaN makes every force NaN, as the sum over all does', &
                 nan_forces == n, real(nan_forces, wp))
    else
      call check('cells: the pairs just inside the range are in contact', at_edge == 20, &
                 real(at_edge, wp))
    end if
  end subroutine cells_same_bits

  !> Disks at random in a side x side box, of radius r0..r0 + 1.
  subroutine random_crowd(side, r0, px, py, pr)
    real(wp), intent(in) :: side, r0
    real(wp), intent(out) :: px(:), py(:), pr(:)
    call random_number(px)
    call random_number(py)
    call random_number(pr)
    px = side*px
    py = side*py
    pr = r0 + pr
  end subroutine random_crowd

end program test_collisions

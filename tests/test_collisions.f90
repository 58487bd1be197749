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
program test_collisions
  use dkt_kinds, only: wp
  use dkt_check, only: check, finish
  use dkt_collisions, only: collision_forces, collision_force_on, repel
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
    call random_number(px)
    call random_number(py)
    call random_number(pr)
    px = 40.0_wp*px
    py = 40.0_wp*py
    pr = 2.0_wp + pr
    call collision_forces(px, py, pr, 40.0_wp, 40.0_wp, ends, eps, eps_ov, xi, fx, fy)
    bad = 0
    do k = 1, n
      call collision_force_on(k, px, py, pr, 40.0_wp, 40.0_wp, ends, eps, eps_ov, xi, gx, gy)
      if (gx /= fx(k) .or. gy /= fy(k)) bad = bad + 1
    end do
    call check('one particle''s force has the bits of collision_forces', bad == 0, real(bad, wp))
    call check('the crowd is in contact', count(fx /= 0.0_wp) > n/2, real(count(fx /= 0.0_wp), wp))
  end subroutine one_particle_same_bits

end program test_collisions

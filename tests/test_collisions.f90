!> Unit tests of the Wan–Turek repulsion (docs/model.md E10–E11):
!>  - no force beyond R_i + R_j + xi; equal and opposite forces along the line of centres;
!>  - inside the range the force is (X_i - X_j)(R_i + R_j + xi - d)^2/eps_p;
!>  - overlapping disks: (X_i - X_j)(R_i + R_j - d)/eps'_p;
!>  - a wall acts as the mirror particle with half the stiffness (E11): the range test is on
!>    d' - 2R, twice the gap to the wall.
!>  - collision_force_on(k) gives particle k's force of collision_forces with the same bits, in a
!>    crowd of disks some touching, some overlapping, some near the walls.
program test_collisions
  use dkt_kinds, only: wp
  use dkt_check, only: check, finish
  use dkt_collisions, only: collision_forces, collision_force_on
  implicit none
  real(wp) :: cx(2), cy(2), x(2), y(2), r(2)
  real(wp), parameter :: eps = 2.0_wp, eps_ov = 0.5_wp, xi = 1.0_wp, big = 1.0e6_wp

  r = [5.0_wp, 3.0_wp]
  ! far apart, far from the walls (width and height huge)
  x = [100.0_wp, 109.5_wp]
  y = [200.0_wp, 200.0_wp]
  call collision_forces(x, y, r, big, big, .true., eps, eps_ov, xi, cx, cy)
  call check('no force beyond R1 + R2 + xi', all([cx, cy] == 0.0_wp), maxval(abs([cx, cy])))

  ! gap 0.4 inside the range along x: |F| = d (xi - gap)^2 / eps
  x = [100.0_wp, 108.4_wp]
  call collision_forces(x, y, r, big, big, .true., eps, eps_ov, xi, cx, cy)
  call check('range force (X1 - X2)(R1 + R2 + xi - d)^2/eps_p', &
             abs(cx(1) - (-8.4_wp*0.6_wp**2/eps)) < 1.0e-12_wp, cx(1))
  call check('equal and opposite, along the line of centres', &
             cx(1) == -cx(2) .and. all(cy == 0.0_wp), cx(1) + cx(2))

  ! overlap 0.5: |F| = d (R1 + R2 - d)/eps'
  x = [100.0_wp, 107.5_wp]
  call collision_forces(x, y, r, big, big, .true., eps, eps_ov, xi, cx, cy)
  call check('overlap force (X1 - X2)(R1 + R2 - d)/eps''_p', &
             abs(cx(1) - (-7.5_wp*0.5_wp/eps_ov)) < 1.0e-12_wp, cx(1))

  ! a disk 5.3 from the left wall: mirror at -5.3, d' = 10.6, 2R = 10, so d' - 2R = 0.6 (twice
  ! the gap to the wall) is inside the range
  call collision_forces([5.3_wp], [200.0_wp], [5.0_wp], big, big, .true., eps, eps_ov, xi, &
                        cx(1:1), cy(1:1))
  call check('wall: mirror particle with half the stiffness (E11)', &
             abs(cx(1) - 10.6_wp*0.4_wp**2/(0.5_wp*eps)) < 1.0e-12_wp, cx(1))
  ! 5.5 from the wall: d' - 2R = 1 = xi, the edge of the range
  call collision_forces([5.5_wp], [200.0_wp], [5.0_wp], big, big, .true., eps, eps_ov, xi, &
                        cx(1:1), cy(1:1))
  call check('wall: no force once d'' - 2R reaches xi', cx(1) == 0.0_wp, cx(1))
  ! the same disk near the bottom end: felt only when the ends are walls
  call collision_forces([200.0_wp], [5.3_wp], [5.0_wp], big, big, .false., eps, eps_ov, xi, &
                        cx(1:1), cy(1:1))
  call check('open ends exert no wall force', cy(1) == 0.0_wp, cy(1))
  call collision_forces([200.0_wp], [5.3_wp], [5.0_wp], big, big, .true., eps, eps_ov, xi, &
                        cx(1:1), cy(1:1))
  call check('closed ends push the disk back', cy(1) > 0.0_wp, cy(1))

  call one_particle_same_bits()

  call finish()

contains

  !> 60 disks of radius 2..3 dropped at random into a 40 x 40 box: many within the range or
  !! overlapping each other or a wall; every particle's force alone equals the crowd's.
  subroutine one_particle_same_bits()
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
    call collision_forces(px, py, pr, 40.0_wp, 40.0_wp, .true., eps, eps_ov, xi, fx, fy)
    bad = 0
    do k = 1, n
      call collision_force_on(k, px, py, pr, 40.0_wp, 40.0_wp, .true., eps, eps_ov, xi, gx, gy)
      if (gx /= fx(k) .or. gy /= fy(k)) bad = bad + 1
    end do
    call check('one particle''s force has the bits of collision_forces', bad == 0, real(bad, wp))
    call check('the crowd is in contact', count(fx /= 0.0_wp) > n/2, real(count(fx /= 0.0_wp), wp))
  end subroutine one_particle_same_bits

end program test_collisions

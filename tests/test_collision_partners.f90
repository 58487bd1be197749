!> Unit test of the contact partners (dkt_collisions collision_partners, used by
!> dkt_particle_motion for the sub-steps of a step): a disk k that stays within `drift` of its
!> start-of-step centre feels, from the partners and walls the list keeps, the force of every
!> candidate and every wall, bit for bit (the others add exact zeros: ±0 to a sum that is never
!> -0). Checked for 40 random crowds of 400 disks (radii 1..4, or all 4; contact ranges 0 to 2;
!> each choice of end walls) with pairs placed exactly at the reach R_i + R_j + xi + drift (and
!> a relative 1e-12 beyond), a disk exactly at that reach from a side wall and from the upper
!> end, and 60 positions of k for each disk: on the circle of radius `drift` (the four axis
!> directions among them) and inside it. A disk with no partner and no wall gets +0 from an
!> empty sum, as the motion takes it; the list is ascending, and it prunes (on average it holds
!> a small part of the candidates).
program test_collision_partners
  use dkt_kinds, only: wp, i8
  use dkt_check, only: check, finish
  use dkt_cells, only: cells_t, cells_build, cells_near
  use dkt_collisions, only: collision_force_on, collision_partners
  implicit none
  integer, parameter :: N = 400, CROWDS = 40, TRIALS = 60
  real(wp), parameter :: DRIFT = 1.0_wp, EPS = 2.0_wp, EPS_OV = 0.5_wp
  real(wp), parameter :: TWO_PI = 6.283185307179586_wp
  real(wp) :: x(N), y(N), r(N), xs(N), ys(N), u, v, fx, fy, gx, gy, rmax, xi, w, h, d, ang
  type(cells_t) :: cells
  integer, allocatable :: near(:), part(:)
  integer :: k, m, np, trial, bad, tested, it, l, seed_size
  integer(i8) :: kept, candidates
  logical :: walls(4), ends(2), ascending
  integer, allocatable :: seed(:)

  call random_seed(size=seed_size)
  allocate (seed(seed_size))
  seed = [(7919*l + 13, l=1, seed_size)]
  call random_seed(put=seed)
  bad = 0
  tested = 0
  kept = 0
  candidates = 0
  ascending = .true.
  do it = 1, CROWDS
    call random_number(x)
    call random_number(y)
    call random_number(r)
    w = 60.0_wp + 20*mod(it, 3)
    h = 50.0_wp + 10*mod(it, 4)
    xi = 0.5_wp*mod(it, 5)
    r = 1.0_wp + 3.0_wp*r
    if (mod(it, 2) == 0) r = 4.0_wp
    x = x*w
    y = y*h
    ! pairs exactly at the reach of the list, and a relative 1e-12 beyond it
    do k = 1, 40, 2
      x(k + 1) = x(k) + (r(k) + r(k + 1) + xi + DRIFT)*(1 + mod(k, 3)*1.0e-12_wp)
      y(k + 1) = y(k)
    end do
    ! a disk whose mirror image across the left side, and one whose image across the upper
    ! end, lies exactly 2r + xi + 2 drift away
    x(41) = r(41) + 0.5_wp*xi + DRIFT
    y(42) = h - r(42) - 0.5_wp*xi - DRIFT
    ends = [mod(it, 3) /= 0, mod(it, 4) /= 0]
    rmax = maxval(r)
    call cells_build(cells, x, y, 2.0_wp*rmax + xi)
    do k = 1, N
      call cells_near(cells, x(k), y(k), r(k) + rmax + xi + 2.0_wp, near, m)
      call collision_partners(k, x, y, r, w, h, ends, xi, DRIFT, near(1:m), part, np, walls)
      do l = 2, np
        if (part(l) <= part(l - 1)) ascending = .false.
      end do
      kept = kept + np
      candidates = candidates + m
      xs = x
      ys = y
      do trial = 1, TRIALS
        call random_number(u)
        call random_number(v)
        ang = TWO_PI*u
        d = DRIFT*sqrt(v)
        if (trial <= 8) d = DRIFT
        if (trial <= 4) ang = 0.25_wp*TWO_PI*(trial - 1)
        xs(k) = x(k) + d*cos(ang)
        ys(k) = y(k) + d*sin(ang)
        if ((xs(k) - x(k))**2 + (ys(k) - y(k))**2 > DRIFT**2) cycle
        call collision_force_on(k, xs, ys, r, w, h, ends, EPS, EPS_OV, xi, fx, fy, near(1:m))
        if (np == 0 .and. .not. any(walls)) then
          gx = 0.0_wp
          gy = 0.0_wp
        else
          call collision_force_on(k, xs, ys, r, w, h, ends, EPS, EPS_OV, xi, gx, gy, &
                                  part(1:np), walls)
        end if
        tested = tested + 1
        if (transfer(fx, 1_i8) /= transfer(gx, 1_i8) .or. &
            transfer(fy, 1_i8) /= transfer(gy, 1_i8)) bad = bad + 1
      end do
    end do
  end do
  ! detail: the positions whose force differs, the positions tested, the mean kept fraction
  call check('the partners give the force of every candidate, bit for bit ', bad == 0, &
             real(bad, wp))
  call check('positions were tested ', tested > CROWDS*N*TRIALS/2, real(tested, wp))
  call check('the partners are in ascending order ', ascending, 0.0_wp)
  call check('the list prunes: under a third of the candidates on average ', &
             3*kept < candidates, real(kept, wp)/real(max(candidates, 1_i8), wp))
  call finish()
end program test_collision_partners

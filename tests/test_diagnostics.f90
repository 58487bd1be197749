!> Unit tests of the pair diagnostics of docs/model.md §6 (module dkt_diagnostics):
!>  - kissing episodes from synthetic D_r(t) series with known answers: none, one, two, a gap
!>    hovering between the enter and release thresholds (one episode, not many), an episode
!>    still open at the end, the thresholds themselves (enter: D_r <= enter starts; release:
!>    only D_r > release ends), and the DKT pattern word for 0, 1, 2 and 3 episodes;
!>  - an analytic series D_r = 2 cos t + 3/2 whose episodes start where it falls to the enter
!>    threshold and end where it rises above the release threshold (hysteresis), to within one
!>    sample;
!>  - D_x, D_y, D_r of two disks in a 3-4-5 geometry;
!>  - the drag coefficient E12 for a known force and velocity, and NaN for a particle at rest;
!>  - the particle speed guard: quiet at or below the limit (a 3-4-5 velocity of speed 5 against
!>    5), failing above it and for a NaN or infinite velocity, naming the first failing
!>    particle, its speed, the step and its centre in cm.
program test_diagnostics
  use ieee_arithmetic, only: ieee_is_nan, ieee_value, ieee_quiet_nan, ieee_positive_inf
  use dkt_kinds, only: wp, pi
  use dkt_check, only: check, finish
  use dkt_diagnostics, only: pair_diag_t, pair_diag_init, pair_diag_update, pair_pattern, &
                             pair_gaps, drag_coefficient, guard_particle_speed
  implicit none
  type(pair_diag_t) :: d
  real(wp), parameter :: enter = 1.0_wp, release = 2.0_wp
  real(wp) :: gx, gy, gr, cd(3), t_end_1, t_end_2, dt, bad
  character(len=:), allocatable :: msg
  integer :: k, n

  ! ---- never: the gap closes to just above the enter threshold and opens again
  call feed(d, [10.0_wp, 6.0_wp, 3.0_wp, 1.5_wp, 1.0001_wp, 1.9_wp, 4.0_wp])
  call check('never: no episode when D_r stays above enter', d%n == 0 .and. &
             .not. d%in_episode, real(d%n, wp))
  call check('never: pattern word', pair_pattern(d) == 'never', real(d%n, wp))

  ! ---- once: times are the sample indices 1, 2, ...; D_r = enter exactly starts (sample 3),
  ! D_r = release exactly does not end (sample 7), the first D_r > release ends (sample 8)
  call feed(d, [5.0_wp, 3.0_wp, 1.0_wp, 0.5_wp, 0.2_wp, 1.5_wp, 2.0_wp, 2.5_wp, 6.0_wp])
  call check('once: one episode', d%n == 1 .and. .not. d%in_episode, real(d%n, wp))
  call check('once: pattern word', pair_pattern(d) == 'once', real(d%n, wp))
  call check('once: starts at the first D_r <= enter (D_r = enter counts)', &
             d%t_start(1) == 3.0_wp, d%t_start(1))
  call check('once: t_end is the last sample with D_r <= release (D_r = release stays in)', &
             d%t_end(1) == 7.0_wp, d%t_end(1))
  call check('once: gap_min is the smallest D_r of the episode', d%gap_min(1) == 0.2_wp, &
             d%gap_min(1))

  ! ---- a gap hovering between enter and release, before and after it first closes: D_r goes
  ! below enter once (sample 4) and then crosses enter many times without exceeding release
  call feed(d, [1.5_wp, 1.9_wp, 1.2_wp, 0.9_wp, 1.8_wp, 0.8_wp, 1.99_wp, 0.7_wp, 1.3_wp, &
                0.95_wp, 2.0_wp, 3.0_wp])
  call check('hovering between enter and release is one episode', d%n == 1, real(d%n, wp))
  call check('hovering: starts at the first D_r <= enter, not before', d%t_start(1) == 4.0_wp, &
             d%t_start(1))
  call check('hovering: ends after the last sample within release', d%t_end(1) == 11.0_wp .and. &
             .not. d%in_episode, d%t_end(1))
  call check('hovering: gap_min', d%gap_min(1) == 0.7_wp, d%gap_min(1))

  ! ---- repeated: two episodes with a release in between
  call feed(d, [4.0_wp, 0.6_wp, 0.3_wp, 1.7_wp, 2.1_wp, 5.0_wp, 0.9_wp, 0.1_wp, 0.4_wp, &
                2.5_wp])
  call check('repeated: two episodes', d%n == 2 .and. .not. d%in_episode, real(d%n, wp))
  call check('repeated: pattern word', pair_pattern(d) == 'repeated', real(d%n, wp))
  call check('repeated: start times', all(d%t_start == [2.0_wp, 7.0_wp]), &
             maxval(abs(d%t_start - [2.0_wp, 7.0_wp])))
  call check('repeated: end times', all(d%t_end == [4.0_wp, 9.0_wp]), &
             maxval(abs(d%t_end - [4.0_wp, 9.0_wp])))
  call check('repeated: smallest gap of each episode', all(d%gap_min == [0.3_wp, 0.1_wp]), &
             maxval(abs(d%gap_min - [0.3_wp, 0.1_wp])))

  ! ---- three episodes are still 'repeated'
  call feed(d, [0.5_wp, 3.0_wp, 0.5_wp, 3.0_wp, 0.5_wp, 3.0_wp])
  call check('three episodes: pattern repeated', d%n == 3 .and. pair_pattern(d) == 'repeated', &
             real(d%n, wp))

  ! ---- an episode still open when the series ends: t_end is the last sample
  call feed(d, [3.0_wp, 2.5_wp, 0.8_wp, 0.4_wp, 0.6_wp, 1.9_wp])
  call check('open at the end: one episode, still open', d%n == 1 .and. d%in_episode, &
             real(d%n, wp))
  call check('open at the end: t_end is the last sample', d%t_end(1) == 6.0_wp, d%t_end(1))
  call check('open at the end: start and gap_min', d%t_start(1) == 3.0_wp .and. &
             d%gap_min(1) == 0.4_wp, d%gap_min(1))

  ! ---- D_r = 2 cos t + 3/2 on [0, 4 pi], enter 0.5, release 1: D_r <= 0.5 where
  ! cos t <= -1/2 (from 2 pi/3), D_r > 1 again where cos t > -1/4 (after 2 pi - acos(-1/4));
  ! the same one period later. Between 4 pi/3 and 2 pi - acos(-1/4) the gap is above enter but
  ! not above release: a rule without hysteresis would end the episode at 4 pi/3.
  dt = 1.0e-3_wp
  n = nint(4.0_wp*pi/dt)
  call pair_diag_init(d, 0.5_wp, 1.0_wp)
  do k = 0, n
    call pair_diag_update(d, k*dt, 2.0_wp*cos(k*dt) + 1.5_wp)
  end do
  t_end_1 = 2.0_wp*pi - acos(-0.25_wp)
  t_end_2 = t_end_1 + 2.0_wp*pi
  call check('cosine: two episodes, both closed', d%n == 2 .and. .not. d%in_episode, &
             real(d%n, wp))
  call check('cosine: episodes start where D_r reaches enter (within one sample)', &
             maxval(abs(d%t_start - [2.0_wp*pi/3.0_wp, 8.0_wp*pi/3.0_wp])) <= dt, &
             maxval(abs(d%t_start - [2.0_wp*pi/3.0_wp, 8.0_wp*pi/3.0_wp])))
  call check('cosine: episodes end where D_r exceeds release (within one sample)', &
             maxval(abs(d%t_end - [t_end_1, t_end_2])) <= dt, &
             maxval(abs(d%t_end - [t_end_1, t_end_2])))
  call check('cosine: gap_min = -1/2 (within the sampling error)', &
             maxval(abs(d%gap_min + 0.5_wp)) <= dt**2, maxval(abs(d%gap_min + 0.5_wp)))

  ! ---- gaps: centres (1, 5) and (4, 1) are 5 apart (3-4-5); radii 0.5 and 1.5
  call pair_gaps(1.0_wp, 5.0_wp, 0.5_wp, 4.0_wp, 1.0_wp, 1.5_wp, gx, gy, gr)
  call check('pair_gaps: D_x = x_1 - x_2, D_y = y_1 - y_2', gx == -3.0_wp .and. gy == 4.0_wp, &
             abs(gx + 3.0_wp) + abs(gy - 4.0_wp))
  call check('pair_gaps: D_r = |X_1 - X_2| - (R_1 + R_2)', abs(gr - 3.0_wp) < 1.0e-14_wp, &
             gr - 3.0_wp)
  ! overlapping disks give a negative D_r
  call pair_gaps(0.0_wp, 0.0_wp, 1.0_wp, 0.0_wp, -1.5_wp, 1.0_wp, gx, gy, gr)
  call check('pair_gaps: overlap is negative', abs(gr + 0.5_wp) < 1.0e-14_wp, gr + 0.5_wp)

  ! ---- E12: F_d = 2, |U|^2 = 3^2 + 4^2 = 25, rho_f = 1.2, D = 0.1: C_d = 2/(0.5 1.2 25 0.1)
  cd(1:1) = drag_coefficient([2.0_wp], [3.0_wp], [-4.0_wp], [1.2_wp], [0.1_wp])
  call check('drag coefficient F_d/(rho_f U^2 D/2)', abs(cd(1) - 2.0_wp/1.5_wp) < 1.0e-14_wp, &
             cd(1) - 2.0_wp/1.5_wp)
  ! elemental: a particle at rest among moving ones gives NaN, the others their values
  cd = drag_coefficient([1.0_wp, 1.0_wp, -1.0_wp], [0.0_wp, 0.0_wp, 1.0_wp], &
                        [0.0_wp, 2.0_wp, 0.0_wp], 1.0_wp, 1.0_wp)
  call check('drag coefficient is NaN at rest', ieee_is_nan(cd(1)), cd(1))
  call check('drag coefficient elemental, signed', abs(cd(2) - 0.5_wp) < 1.0e-14_wp .and. &
             abs(cd(3) + 2.0_wp) < 1.0e-14_wp, cd(2) - 0.5_wp)

  ! ---- particle speed guard: two particles, lattice units, dx = 0.5 cm
  msg = speed_failure(3.0_wp, 4.0_wp, 5.0_wp)
  call check('speed guard: |U| = 5 at the limit 5 passes (3-4-5)', len(msg) == 0, 0.0_wp)
  msg = speed_failure(3.0_wp, 4.0_wp, 4.99_wp)
  call check('speed guard: |U| = 5 above the limit 4.99 fails', &
             index(msg, 'particle 2 moves') > 0 .and. index(msg, 'at step 7') > 0 .and. &
             index(msg, 'run.particle_speed_limit') > 0, real(len(msg), wp))
  call check('speed guard: centre in cm, y = 12 dx', index(msg, '6.0000E+000') > 0, 0.0_wp)
  bad = ieee_value(bad, ieee_quiet_nan)
  msg = speed_failure(bad, 0.0_wp, 1.0_wp)
  call check('speed guard: a NaN velocity fails', index(msg, 'particle 2 moves') > 0, 0.0_wp)
  bad = ieee_value(bad, ieee_positive_inf)
  msg = speed_failure(0.0_wp, bad, 1.0_wp)
  call check('speed guard: an infinite velocity fails', index(msg, 'particle 2') > 0, 0.0_wp)

  call finish()

contains

  !> A fresh diagnostics with enter = 1, release = 2, fed `gaps` at times 1, 2, 3, ...
  subroutine feed(d, gaps)
    type(pair_diag_t), intent(out) :: d
    real(wp), intent(in) :: gaps(:)
    integer :: i
    call pair_diag_init(d, enter, release)
    do i = 1, size(gaps)
      call pair_diag_update(d, real(i, wp), gaps(i))
    end do
  end subroutine feed

  !> The speed guard's message for particle 1 at rest and particle 2 at (u, v), centres
  !! (4, 6) and (10, 12) lattice units, dx = 0.5 cm, at step 7
  function speed_failure(u, v, limit) result(msg)
    real(wp), intent(in) :: u, v, limit
    character(len=:), allocatable :: msg
    msg = guard_particle_speed([0.0_wp, u], [0.0_wp, v], [4.0_wp, 10.0_wp], [6.0_wp, 12.0_wp], &
                               limit, 7, 0.7_wp, 0.5_wp, 0.0_wp)
  end function speed_failure

end program test_diagnostics

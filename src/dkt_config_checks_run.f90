!> The checks of a configuration that need its time step or lattice units (the time step, the
!> run length, the velocity scale, the measured stable region, the paths of prescribed
!> particles, the kissing thresholds, the run's duration), and config_checks, the sequence of
!> every check: each key's range, then the rules that join keys. Messages name where the keys
!> were set (file:line or --set), else the file.
module dkt_config_checks_run
  use ieee_arithmetic, only: ieee_is_finite
  use dkt_kinds, only: wp, cs2, pi
  use dkt_registry, only: registry_t, check_key
  use dkt_text, only: quoted, fmt_num, itoa
  use dkt_config_types, only: config_t, MAX_STEPS
  use dkt_config_scene, only: pair_d1, kiss_thresholds, kiss_enter_cells, dx_knob, &
                              velocity_scale_source, pair_named
  use dkt_config_lattice, only: lattice_params_t, lattice_from
  use dkt_config_checks, only: check_t, chk_domain, chk_particles, chk_contacts, chk_pair, &
                               chk_window, val, src, from, item, dx_text, power, round6, &
                               CONTACT_TOL
  implicit none
  private
  public :: config_checks

  !> The measured stable region of a settling disk (docs/stability.md, from
  !! docs/stability_map.csv: tests/perf/stability_map.py, input/single.nml at 10 spacings per
  !! diameter): at each MAP_TAU, the largest lattice Reynolds number U dx/nu = Re_p/N (N spacings
  !! per diameter) below which every run of the grid finished stable. Beyond it, runs were
  !! stopped by the Mach guard (or not measured); U is the velocity scale of the input check.
  real(wp), parameter :: MAP_TAU(*) = [0.501_wp, 0.505_wp, 0.51_wp, 0.52_wp, 0.55_wp, 0.6_wp, &
                                       0.65_wp, 0.8_wp, 1.0_wp, 1.5_wp, 2.0_wp]
  real(wp), parameter :: MAP_RE_CELL(*) = [120.0_wp, 60.0_wp, 30.0_wp, 30.0_wp, 10.0_wp, 3.0_wp, &
                                           3.0_wp, 3.0_wp, 1.0_wp, 1.0_wp, 0.3_wp]
  !> a time step outside DT_MIN..DT_MAX s comes from a viscosity or density in the wrong units
  !! (no flow on a cm lattice needs it), and makes the lattice-unit forces under- or overflow
  real(wp), parameter :: DT_MIN = 1.0e-12_wp, DT_MAX = 1.0e6_wp
  character(len=*), parameter :: NL = new_line('a')

contains

  !> Every check of configuration `c` with registry `reg`: each key's range (unless
  !! `keys_checked`: the caller did it), then the rules that join keys, in order. `err`: the
  !! first problem, '' if none. `warnings`: newline-separated, '' if none; incomplete when
  !! `err` is set. `lp`: the lattice units of `c`, derived once here (valid when err is '').
  subroutine config_checks(c, reg, keys_checked, err, warnings, lp)
    type(config_t), intent(in), target :: c
    type(registry_t), intent(in), target :: reg
    logical, intent(in) :: keys_checked
    character(len=:), allocatable, intent(out) :: err
    character(len=:), allocatable, intent(out) :: warnings
    type(lattice_params_t), intent(out) :: lp
    type(check_t) :: ck
    integer :: j
    err = ''
    warnings = ''
    if (.not. keys_checked) then
      do j = 1, size(reg%keys)
        call check_key(reg%keys(j), c%file, err)
        if (len(err) > 0) return
      end do
    end if
    ck%c => c
    ck%reg => reg
    ck%warnings = ''
    call chk_domain(ck, err)
    if (len(err) > 0) return
    call chk_particles(ck, err)
    if (len(err) > 0) return
    ! a pair too close is the user's pair.dh, before it shows as an overlap of &particles
    if (c%pair%gamma > 0.0_wp) call chk_pair(ck, err)
    if (len(err) > 0) return
    if (c%diagnostics%pair .and. c%particles%count < 2) then
      ! accepted and then ignored would be worse: a pair needs two particles
      err = from(ck, 'diagnostics.pair particles.count')//': &diagnostics pair = '// &
            val(ck, 'diagnostics', 'pair')//' with '//itoa(c%particles%count)//' particle'// &
            trim(merge('s', ' ', c%particles%count /= 1))//'; allowed: pair = .true. with '// &
            'at least 2 particles (particles 1 and 2 are the pair)'
      return
    end if
    call chk_contacts(ck, err)
    if (len(err) > 0) return
    if (c%window%enabled) call chk_window(ck, err)
    if (len(err) > 0) return
    ! the derived quantities, before anything that uses them: keys in range can still give
    ! dt = 0 or Infinity and NaN in every lattice-unit quantity after it. These two work with
    ! logarithms, so that no overflow happens (a checked build traps it) before they refuse.
    call chk_time_step(ck, err)
    if (len(err) > 0) return
    call chk_steps(ck, err)
    if (len(err) > 0) return
    ck%lp = lattice_from(c)
    call chk_prescribed_paths(ck, err)
    if (len(err) > 0) return
    call chk_velocity_scale(ck, err)
    if (len(err) > 0) return
    call chk_stability_map(ck)
    if (pair_named(c)) then
      call chk_thresholds(ck, err)
      if (len(err) > 0) return
      call chk_duration(ck)
    end if
    warnings = ck%warnings
    lp = ck%lp
  end subroutine config_checks

  !> nu = viscosity/density and dt = nu_lb dx^2/nu (E3) are finite, and dt lies within
  !! DT_MIN..DT_MAX s: a viscosity or density far off (wrong units, a typing error) gives
  !! dt = 0 or Infinity and NaN in every lattice-unit quantity derived from it. In
  !! logarithms (both keys are > 0), so that computing them cannot overflow.
  subroutine chk_time_step(ck, err)
    type(check_t), intent(inout), target :: ck
    character(len=:), allocatable, intent(inout) :: err
    real(wp) :: nu_log, dt_log
    character(len=:), allocatable :: head
    type(config_t), pointer :: c
    c => ck%c
    nu_log = log10(c%fluid%viscosity) - log10(c%fluid%density)
    dt_log = log10(cs2*(c%lbm%tau - 0.5_wp)) + 2.0_wp*log10(c%lbm%dx) - nu_log
    head = from(ck, 'fluid.viscosity fluid.density lbm.tau lbm.dx lbm.cells_per_diameter')// &
           ': &fluid viscosity = '//val(ck, 'fluid', 'viscosity')//' g/(cm s) and density = '// &
           val(ck, 'fluid', 'density')//' g/cm^3 give '
    if (nu_log < log10(tiny(1.0_wp)) .or. nu_log > log10(huge(1.0_wp))) then
      err = head//'the kinematic viscosity nu = viscosity/density = '//power(nu_log)// &
            ' cm^2/s; allowed: a finite nu > 0 (water: viscosity = 0.01, density = 1.0); '// &
            'change &fluid viscosity or density'
    else if (dt_log < log10(DT_MIN) .or. dt_log > log10(DT_MAX)) then
      err = head//'nu = '//power(nu_log)//' cm^2/s, and with '//dx_text(ck)// &
            ' and &lbm tau = '//val(ck, 'lbm', 'tau')//' the time step dt = (tau - 1/2)/3 '// &
            'dx^2/nu = '//power(dt_log)//' s; allowed: '//fmt_num(DT_MIN)//' s <= dt <= '// &
            fmt_num(DT_MAX)//' s; check &fluid viscosity (g/(cm s)) and density (g/cm^3) '// &
            '(water: 0.01 and 1.0), then '
      ! a smaller dx makes dt smaller (dt ~ dx^2)
      if (dt_log > log10(DT_MAX)) then
        err = err//dx_knob(c)
      else
        err = err//dx_knob(c, larger=.true.)
      end if
    end if
  end subroutine chk_time_step

  !> t_end/dt rounds to 1..MAX_STEPS time steps (run.steps > 0 is range-checked as a key).
  !! dt is within DT_MIN..DT_MAX here; t_end/dt is compared in logarithms as well.
  subroutine chk_steps(ck, err)
    type(check_t), intent(inout), target :: ck
    character(len=:), allocatable, intent(inout) :: err
    character(len=*), parameter :: STEP_KEYS = 'run.t_end lbm.tau lbm.dx '// &
                                   'lbm.cells_per_diameter fluid.viscosity fluid.density'
    real(wp) :: dt, n_log
    type(config_t), pointer :: c
    c => ck%c
    if (c%run%steps > 0) return
    dt = cs2*(c%lbm%tau - 0.5_wp)*c%lbm%dx**2/(c%fluid%viscosity/c%fluid%density)
    n_log = log10(c%run%t_end) - log10(dt)
    if (n_log < log10(0.5_wp)) then
      err = from(ck, STEP_KEYS)//': &run t_end = '//val(ck, 'run', 't_end')//' s gives 0 time '// &
            'steps: dt = '//fmt_num(dt)//' s (from '//dx_text(ck)//', &lbm tau = '// &
            val(ck, 'lbm', 'tau')//' and &fluid viscosity/density); allowed: t_end >= dt/2 = '// &
            fmt_num(0.5_wp*dt)//' s, or &run steps >= 1'
    else if (n_log > log10(MAX_STEPS)) then
      err = from(ck, STEP_KEYS)//': &run t_end = '//val(ck, 'run', 't_end')//' s gives '// &
            power(n_log)//' time steps of dt = '//fmt_num(dt)//' s (from '// &
            dx_text(ck)//', &lbm tau = '//val(ck, 'lbm', 'tau')//' and &fluid viscosity/'// &
            'density); allowed: at most '//itoa(nint(MAX_STEPS))//' steps, i.e. t_end <= '// &
            fmt_num(round6(MAX_STEPS*dt, down=.true.))//' s; make t_end smaller, or dt '// &
            'larger: raise lbm.tau, or '//dx_knob(c, larger=.true.)
    end if
  end subroutine chk_steps

  !> The velocity scale of the run is finite, and a prescribed particle (which moves at its
  !! velocity whatever the flow does, so the fluid next to it does too) is not faster than
  !! run.mach_limit allows: the guard would otherwise stop the run at its first check, and
  !! name a node instead of the particle.
  subroutine chk_velocity_scale(ck, err)
    type(check_t), intent(inout), target :: ck
    character(len=:), allocatable, intent(inout) :: err
    real(wp) :: speed, u_max
    integer :: k
    type(config_t), pointer :: c
    type(lattice_params_t), pointer :: lp
    c => ck%c
    lp => ck%lp
    if (.not. (ieee_is_finite(lp%u_scale_lb) .and. ieee_is_finite(lp%mach))) then
      err = src(ck, 'density', 'fluid')//': the expected velocity scale is '// &
            fmt_num(lp%u_scale_lb)//' in lattice units, from '//velocity_scale_source(c)// &
            ' with dt = '//fmt_num(lp%dt)//' s and dx = '//fmt_num(lp%dx)// &
            ' cm; allowed: a finite velocity scale; change the key named'
      return
    end if
    u_max = c%run%mach_limit*sqrt(cs2)*lp%dx/lp%dt
    associate (p => c%particles)
      ! any particle, free ones too: the particle guard would stop the run at step 1
      do k = 1, p%count
        speed = hypot(p%u(k), p%v(k))
        if (speed*lp%dt/lp%dx <= c%run%particle_speed_limit) cycle
        err = from(ck, 'particles.v particles.u run.particle_speed_limit lbm.dx lbm.tau')// &
              ': '//item('u', k, p%u(k))//', v('//itoa(k)//') = '//fmt_num(p%v(k))// &
              ': particle '//itoa(k)//' starts at '// &
              fmt_num(round6(speed*lp%dt/lp%dx))//' lattice spacings per step (dx = '// &
              fmt_num(lp%dx)//' cm, dt = '//fmt_num(lp%dt)//' s), above &run '// &
              'particle_speed_limit = '//val(ck, 'run', 'particle_speed_limit')//'; allowed: '// &
              'a speed up to '// &
              fmt_num(round6(c%run%particle_speed_limit*lp%dx/lp%dt, down=.true.))// &
              ' cm/s; lower u('//itoa(k)//') and v('//itoa(k)//'), or '//dx_knob(c)// &
              ' or lower &lbm tau (both shrink dt/dx)'
        return
      end do
      do k = 1, p%count
        if (p%motion(k) /= 'prescribed') cycle
        speed = hypot(p%u(k), p%v(k))
        if (speed <= u_max) cycle
        err = from(ck, 'particles.v particles.u run.mach_limit lbm.dx lbm.tau')//': '// &
              item('u', k, p%u(k))//', v('//itoa(k)//') = '//fmt_num(p%v(k))// &
              ' with motion('//itoa(k)//') = ''prescribed'': particle '//itoa(k)// &
              ' moves at '//fmt_num(speed)//' cm/s, Mach '// &
              fmt_num(round6(speed*lp%dt/lp%dx/sqrt(cs2)))// &
              ' on this lattice (dx = '//fmt_num(lp%dx)//' cm, dt = '//fmt_num(lp%dt)// &
              ' s), above &run mach_limit = '//val(ck, 'run', 'mach_limit')//'; allowed: a '// &
              'speed up to '//fmt_num(round6(u_max, down=.true.))//' cm/s; lower u('// &
              itoa(k)//') and v('//itoa(k)//'), or '//dx_knob(c)// &
              ' or lower &lbm tau (both shrink dt)'
        return
      end do
    end associate
  end subroutine chk_velocity_scale

  !> A warning when a free particle's expected Reynolds number lies outside the measured
  !! stable region at this tau (MAP_TAU, MAP_RE_CELL; between two measured taus the smaller
  !! limit holds). The map's runs were single disks on the MRT model; the limit is in lattice
  !! units, Re_p/N = U dx/nu, so that a finer lattice raises the allowed Re_p with N.
  subroutine chk_stability_map(ck)
    type(check_t), intent(inout), target :: ck
    real(wp) :: nu, u, re_p, re_max, n_d
    integer :: k, i
    character(len=:), allocatable :: where, advice
    type(config_t), pointer :: c
    c => ck%c
    nu = c%fluid%viscosity/c%fluid%density
    re_max = 0.0_wp
    where = 'outside the measured tau range '//fmt_num(MAP_TAU(1))//' to '// &
            fmt_num(MAP_TAU(size(MAP_TAU)))
    advice = 'choose lbm.tau within that range'
    do i = 1, size(MAP_TAU) - 1
      if (c%lbm%tau >= MAP_TAU(i) .and. c%lbm%tau <= MAP_TAU(i + 1)) then
        re_max = min(MAP_RE_CELL(i), MAP_RE_CELL(i + 1))
        where = ''
        advice = dx_knob(c)//' (Re_p/N falls with dx), or slow the particle'
        exit
      end if
    end do
    associate (p => c%particles)
      do k = 1, p%count
        if (p%motion(k) /= 'free') cycle
        u = max(hypot(p%u(k), p%v(k)), sqrt(0.5_wp*pi*p%diameter(k)* &
                                            abs(p%density(k)/c%fluid%density - 1.0_wp)* &
                                            p%gravity))
        n_d = p%diameter(k)/c%lbm%dx
        re_p = u*p%diameter(k)/nu
        if (re_p/n_d <= re_max) cycle
        if (len(where) == 0) where = 'above the measured stable Re_p/N = '// &
                                     fmt_num(round6(re_max))//' at this tau, i.e. Re_p = '// &
                                     fmt_num(round6(re_max*n_d))//' on this lattice'
        if (len(ck%warnings) > 0) ck%warnings = ck%warnings//NL
        ck%warnings = ck%warnings//src(ck, 'tau', 'lbm')//': &lbm tau = '//val(ck, 'lbm', 'tau')// &
                      ' and particle '//itoa(k)//'''s expected Reynolds number Re_p = U D/nu = '// &
                      fmt_num(round6(re_p))//' (U = '//fmt_num(round6(u))//' cm/s, '// &
                      fmt_num(round6(n_d))//' spacings per diameter) lie '//where// &
                      ' (docs/stability.md, docs/stability_map.csv); the run may be stopped by '// &
                      'a guard; '//advice
        return
      end do
    end associate
  end subroutine chk_stability_map

  !> A prescribed particle moves in a straight line at its constant velocity, so where it is
  !! at the run's end (steps x dt) is known now: its path must stay in the channel (a wall
  !! at least one radius away, an open end not passed by its centre) and not run into a fixed
  !! or another prescribed particle; neither can make way, and the run would go on with a
  !! particle outside the lattice or two solids in one place.
  subroutine chk_prescribed_paths(ck, err)
    type(check_t), intent(inout), target :: ck
    character(len=:), allocatable, intent(inout) :: err
    real(wp) :: t_run, t_hit
    integer :: k, m
    character(len=:), allocatable :: head, what
    type(config_t), pointer :: c
    type(lattice_params_t), pointer :: lp
    c => ck%c
    lp => ck%lp
    t_run = lp%steps*lp%dt
    associate (p => c%particles, d => c%domain)
      do k = 1, p%count
        if (p%motion(k) /= 'prescribed') cycle
        head = from(ck, 'particles.v particles.u particles.x particles.y run.t_end run.steps')// &
               ': &particles motion('//itoa(k)//') = ''prescribed'' with u('//itoa(k)// &
               ') = '//fmt_num(p%u(k))//', v('//itoa(k)//') = '//fmt_num(p%v(k))// &
               ' cm/s from (x, y) = ('//fmt_num(p%x(k))//', '//fmt_num(p%y(k))//') cm: '
        what = ''
        t_hit = huge(1.0_wp)
        call leaves(ck, k, p%x(k), p%u(k), d%width, d%sides == 'wall', d%sides == 'wall', 'x', &
                    'side wall', 'side wall', what, t_hit)
        ! in a window the lattice follows the free particles; the run checks y as it goes
        if (.not. c%window%enabled) &
          call leaves(ck, k, p%y(k), p%v(k), d%height, d%lower == 'wall', d%upper == 'wall', &
                      'y', 'lower end', 'upper end', what, t_hit)
        do m = 1, p%count
          if (m == k .or. p%motion(m) == 'free') cycle
          if (p%motion(m) == 'prescribed' .and. m < k) cycle ! the pair was checked from m
          call meets(ck, k, m, what, t_hit)
        end do
        if (len(what) > 0) then
          err = head//what//' at t = '//fmt_num(round6(t_hit))//' s, before the run '// &
                'ends at t = '//fmt_num(round6(t_run))//' s (&run t_end/steps); allowed: '// &
                'a path that stays clear until the end; change u('//itoa(k)//'), v('// &
                itoa(k)//'), x('//itoa(k)//'), y('//itoa(k)//'), or end the run before '// &
                't = '//fmt_num(round6(t_hit))//' s'
          return
        end if
      end do
    end associate
  end subroutine chk_prescribed_paths

  !> The first time in 0..t_run at which particle `k`, moving at `vel` from `pos` along
  !! one axis of `length`, touches a wall (`lo_wall`, `hi_wall`: at least one radius) or takes
  !! its centre past an open end; `what` and `t_hit` keep the earliest event.
  subroutine leaves(ck, k, pos, vel, length, lo_wall, hi_wall, key, lo_name, hi_name, what, &
                    t_hit)
    type(check_t), intent(in), target :: ck
    integer, intent(in) :: k
    real(wp), intent(in) :: pos, vel, length
    logical, intent(in) :: lo_wall, hi_wall
    character(len=*), intent(in) :: key, lo_name, hi_name
    character(len=:), allocatable, intent(inout) :: what
    real(wp), intent(inout) :: t_hit
    real(wp) :: r, lo, hi, t, t_run
    t_run = ck%lp%steps*ck%lp%dt
    r = 0.5_wp*ck%c%particles%diameter(k)
    lo = merge(r, 0.0_wp, lo_wall)
    hi = merge(length - r, length, hi_wall)
    if (vel < 0.0_wp) then
      t = (lo - pos)/vel
      if (t <= t_run .and. t < t_hit) then
        t_hit = t
        what = 'its '//trim(merge('surface', 'centre ', lo_wall))//' reaches the '// &
               lo_name//' at '//key//' = 0'
      end if
    else if (vel > 0.0_wp) then
      t = (hi - pos)/vel
      if (t <= t_run .and. t < t_hit) then
        t_hit = t
        what = 'its '//trim(merge('surface', 'centre ', hi_wall))//' reaches the '// &
               hi_name//' at '//key//' = '//fmt_num(length)
      end if
    end if
  end subroutine leaves

  !> The first time in 0..t_run at which prescribed particle `k` and fixed or prescribed
  !! particle `m` come within the contact distance (d_k + d_m)/2 (they move in straight
  !! lines, so the gap is a quadratic in time).
  subroutine meets(ck, k, m, what, t_hit)
    type(check_t), intent(in), target :: ck
    integer, intent(in) :: k, m
    character(len=:), allocatable, intent(inout) :: what
    real(wp), intent(inout) :: t_hit
    real(wp) :: dx0, dy0, wx, wy, a, b, q, reach, disc, t
    associate (p => ck%c%particles, lp => ck%lp)
      dx0 = p%x(k) - p%x(m)
      dy0 = p%y(k) - p%y(m)
      wx = p%u(k) - merge(p%u(m), 0.0_wp, p%motion(m) == 'prescribed')
      wy = p%v(k) - merge(p%v(m), 0.0_wp, p%motion(m) == 'prescribed')
      reach = 0.5_wp*(p%diameter(k) + p%diameter(m))*(1.0_wp - CONTACT_TOL)
      a = wx*wx + wy*wy
      b = dx0*wx + dy0*wy
      q = dx0*dx0 + dy0*dy0 - reach*reach
      if (a <= 0.0_wp .or. b >= 0.0_wp) return ! not approaching
      disc = b*b - a*q
      if (disc <= 0.0_wp) return               ! passes by
      t = (-b - sqrt(disc))/a
      if (t <= lp%steps*lp%dt .and. t < t_hit) then
        t_hit = max(t, 0.0_wp)
        what = 'it runs into particle '//itoa(m)//' (motion('//itoa(m)//') = '// &
               quoted(trim(p%motion(m)))//': the centres come within (diameter('//itoa(k)// &
               ') + diameter('//itoa(m)//'))/2 = '// &
               fmt_num(0.5_wp*(p%diameter(k) + p%diameter(m)))//' cm)'
      end if
    end associate
  end subroutine meets

  !> The episode thresholds of &diagnostics (in spacings) leave a hysteresis: release > enter.
  !! With enter_cells = 0 the entry gap follows collision.range (kiss_enter_cells), and the
  !! message says so.
  subroutine chk_thresholds(ck, err)
    type(check_t), intent(inout), target :: ck
    character(len=:), allocatable, intent(inout) :: err
    real(wp) :: d1, enter, release
    character(len=:), allocatable :: cells_rule, smaller
    type(config_t), pointer :: c
    c => ck%c
    d1 = pair_d1(c)/c%lbm%dx
    call kiss_thresholds(c, enter, release)
    cells_rule = ''
    smaller = 'enter_cells, enter_d1'
    if (c%diagnostics%enter_cells <= 0.0_wp) then
      cells_rule = ' (0: collision.range + 1 = '//fmt_num(kiss_enter_cells(c))// &
                   ' spacings, collision.range = '//val(ck, 'collision', 'range')//')'
      smaller = 'collision.range, enter_d1, or enter_cells > 0'
    end if
    associate (g => c%diagnostics)
      if (release <= enter) &
        err = from(ck, 'diagnostics.release_cells diagnostics.release_d1 '// &
                   'diagnostics.enter_cells diagnostics.enter_d1 collision.range lbm.dx '// &
                   'lbm.cells_per_diameter')//': &diagnostics release_cells = '// &
              val(ck, 'diagnostics', 'release_cells')//' and release_d1 = '// &
              val(ck, 'diagnostics', 'release_d1')//' give a release gap of '// &
              fmt_num(release)//' spacings, not above the entry gap of '// &
              fmt_num(enter)//' spacings from enter_cells = '// &
              val(ck, 'diagnostics', 'enter_cells')//cells_rule//' and enter_d1 = '// &
              val(ck, 'diagnostics', 'enter_d1')//' (D_1 = '//fmt_num(d1)// &
              ' spacings); allowed: release_cells > '//fmt_num(enter)//' or release_d1 > '// &
              fmt_num(enter/d1)//', or a smaller entry gap ('//smaller//')'
    end associate
  end subroutine chk_thresholds

  !> A warning when the run looks too short to see the pair kiss and separate: the initial
  !! surface gap closed at a tenth of the settling-velocity scale u_g = sqrt(pi D_1/2
  !! (rho_p/rho_f - 1) g) of the larger particle (drafting in case0 closes at about that
  !! rate), plus five D_1/u_g for the kiss and the separation. A rough estimate, on purpose.
  subroutine chk_duration(ck)
    type(check_t), intent(inout), target :: ck
    real(wp) :: gap, u_g, t_need, t_run
    type(config_t), pointer :: c
    type(lattice_params_t), pointer :: lp
    c => ck%c
    lp => ck%lp
    associate (p => c%particles)
      if (any(p%motion(1:2) /= 'free')) return
      gap = hypot(p%x(1) - p%x(2), p%y(1) - p%y(2)) - 0.5_wp*(p%diameter(1) + p%diameter(2))
      u_g = sqrt(0.5_wp*pi*pair_d1(c)* &
                 abs(maxval(p%density(1:2))/c%fluid%density - 1.0_wp)*p%gravity)
      if (u_g <= 0.0_wp) return
      t_need = gap/(0.1_wp*u_g) + 5.0_wp*pair_d1(c)/u_g
      t_run = lp%steps*lp%dt
      if (t_run >= t_need) return
      if (c%run%steps == 0) t_run = c%run%t_end ! as typed, not steps x dt
      if (len(ck%warnings) > 0) ck%warnings = ck%warnings//NL
      ck%warnings = ck%warnings//src(ck, 't_end', 'run')//': &run t_end = '//fmt_num(t_run)// &
                    ' s may be too short to classify the DKT pattern of particles 1 and 2: '// &
                    'closing their gap of '//fmt_num(gap)//' cm at a tenth of the settling '// &
                    'velocity scale and separating takes about '//fmt_num(t_need)// &
                    ' s; a pattern ''never'' or ''once'' may only mean the run stopped early'
    end associate
  end subroutine chk_duration

end module dkt_config_checks_run

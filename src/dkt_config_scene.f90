!> The scene-level keys turned into plain ones (&pair into particles 1 and 2,
!> lbm.cells_per_diameter into dx, &window into the domain's height and ends, lbm.mach into
!> tau), and the quantities of a scene several places read: D_1, the largest diameter, the
!> window's lower end, the kissing thresholds, the velocity scale and what sets dx.
module dkt_config_scene
  use ieee_arithmetic, only: ieee_is_finite
  use dkt_kinds, only: wp, cs2, pi
  use dkt_registry, only: registry_t, blame
  use dkt_text, only: fmt_num, itoa
  use dkt_config_types, only: config_t, TAU_MAX
  implicit none
  private
  public :: expand, pair_d1, largest_diameter, window_bottom, kiss_enter_cells, kiss_thresholds, &
            pair_named, window_max_above
  public :: dx_knob, velocity_scale, velocity_scale_source, compressibility_class

  !> the smallest tau lbm.mach may set: nu_lb >= 1/300, the 0.01 above 1/2 keeps clear of the
  !! stability edge of MRT near tau = 1/2 (the window test runs at 0.52; docs/model.md §1)
  real(wp), parameter :: TAU_MACH_MIN = 0.51_wp
  !> upper ends of the compressibility error classes in Ma^2 (docs/model.md §1, "Mach-aware
  !! set-up", ties them to the measured window table): negligible, small, noticeable; above
  !! the last one, large
  real(wp), parameter, public :: MA2_CLASS_TOPS(3) = [1.0e-3_wp, 1.0e-2_wp, 5.0e-2_wp]
  !> the longest the default window.max_above = -1 lets a window grow, in window.above:
  !! 20 x 15 D_1 = 300 D_1 for the paper's window (docs/model.md §5)
  real(wp), parameter, public :: WINDOW_AUTO_CAP = 20.0_wp

contains

  !> Turn the scene-level keys into the plain ones, in place: &pair into particles 1 and 2,
  !! lbm.cells_per_diameter into dx, &window into the domain's height and ends. Keys were range
  !! checked; `err` names what cannot be combined. Applying it twice changes nothing more.
  subroutine expand(c, reg, err)
    type(config_t), intent(inout) :: c
    type(registry_t), intent(in) :: reg
    character(len=:), allocatable, intent(out) :: err
    real(wp) :: d_min, d1
    integer :: lo, hi
    err = ''
    associate (p => c%particles, q => c%pair)
      if (q%gamma > 0.0_wp) then
        if (p%count > 0) then
          err = blame(reg, 'particles.count pair.gamma', c%file)//': &pair gamma = '// &
                fmt_num(q%gamma)//' and &particles count = '//itoa(p%count)//': a pair '// &
                'scene sets its two particles itself; allowed: count = 0 with gamma > 0, '// &
                'or gamma = 0 to take the particles from &particles'
          return
        end if
        ! particle 1 is the larger (D_1), particle 2 the smaller; `upper` says which is above
        hi = merge(1, 2, q%upper == 'larger')
        lo = 3 - hi
        p%count = 2
        p%diameter(1:2) = [q%d1, q%d1/q%gamma]
        p%density(1:2) = q%density
        p%motion(1:2) = 'free'
        p%u(1:2) = 0.0_wp
        p%v(1:2) = 0.0_wp
        p%omega(1:2) = 0.0_wp
        p%x(lo) = 0.5_wp*c%domain%width
        p%x(hi) = 0.5_wp*c%domain%width + q%x_offset
        p%y(hi) = q%y_upper
        p%y(lo) = q%y_upper - q%dh*q%d1
      end if
      if (c%lbm%cells_per_diameter > 0.0_wp) then
        if (p%count == 0) then
          err = blame(reg, 'lbm.cells_per_diameter particles.count', c%file)// &
                ': &lbm cells_per_diameter = '//fmt_num(c%lbm%cells_per_diameter)// &
                ' in a scene without particles; allowed: 0 (set dx instead), or particles'
          return
        end if
        ! the nearest spacing that puts a whole number of cells across the channel
        d_min = minval(p%diameter(1:p%count))
        c%lbm%dx = c%domain%width/real(max(3, nint(c%domain%width*c%lbm%cells_per_diameter/ &
                                                   d_min)), wp)
      end if
      if (c%window%enabled) then
        if (count(p%motion(1:p%count) == 'free') == 0) then
          err = blame(reg, 'window.enabled particles.motion particles.count', c%file)// &
                ': &window enabled = .true. '// &
                'with '//itoa(count(p%motion(1:p%count) == 'free'))//' free particles '// &
                '(count = '//itoa(p%count)//'): the window follows the lowest '// &
                'free particle; allowed: a scene with free particles (&particles or &pair)'
          return
        end if
        d1 = largest_diameter(c)
        c%domain%height = real(max(3, nint((c%window%below + c%window%above)*d1/c%lbm%dx)), wp) &
                          *c%lbm%dx
        c%domain%lower = 'velocity'
        c%domain%upper = 'outflow'
        c%inlet%velocity = 0.0_wp
        c%inlet%profile = 'uniform'
        c%inlet%ramp_time = 0.0_wp
      end if
    end associate
    if (c%lbm%mach > 0.0_wp) call tau_from_mach()
  contains
    !> lbm.mach > 0: tau = 1/2 + Ma nu/(c_s U dx) (E3 with u_lb = U dt/dx = Ma c_s), in place
    !! of lbm.tau, which is then not used; refused when it falls outside
    !! TAU_MACH_MIN..TAU_MAX, when the scene has no velocity scale, or above run.mach_limit.
    subroutine tau_from_mach()
      character(len=:), allocatable :: source, head, knob
      real(wp) :: u, nu, tau, per_tau
      nu = c%fluid%viscosity/c%fluid%density
      call velocity_scale(c, u, source)
      head = blame(reg, 'lbm.mach', c%file)//': &lbm mach = '//fmt_num(c%lbm%mach)
      if (.not. (u > 0.0_wp .and. ieee_is_finite(u))) then
        err = head//' in a scene whose velocity scale is '//fmt_num(u)//' cm/s (largest: '// &
              source//'): a Mach target needs a moving scene; allowed: lbm.mach = 0 (set '// &
              'lbm.tau instead), or a scene with an inlet, initial or body-force flow or '// &
              'moving particles'
        return
      end if
      if (c%lbm%mach > c%run%mach_limit) then
        err = head//' is above &run mach_limit = '//fmt_num(c%run%mach_limit)// &
              ', at which the guard stops the run; allowed: 0 < mach <= mach_limit; lower '// &
              'lbm.mach'
        return
      end if
      ! Ma per unit of tau - 1/2 on this lattice: Ma = (tau - 1/2) c_s U dx/nu
      per_tau = sqrt(cs2)*u*c%lbm%dx/nu
      tau = 0.5_wp + c%lbm%mach/per_tau
      if (tau < TAU_MACH_MIN .or. tau > TAU_MAX .or. .not. ieee_is_finite(tau)) then
        ! tau - 1/2 ~ mach/dx: a tau too large comes down with a larger dx, and vice versa
        knob = dx_knob(c, larger=tau > TAU_MAX)
        err = head//' needs tau = 1/2 + mach nu/(c_s U dx) = '//fmt_num(tau)// &
              ' with the velocity scale U = '//fmt_num(u)//' cm/s (from '//source// &
              '), dx = '//fmt_num(c%lbm%dx)//' cm and nu = '//fmt_num(nu)// &
              ' cm^2/s; allowed: '//fmt_num(TAU_MACH_MIN)//' <= tau <= '// &
              fmt_num(TAU_MAX)//', i.e. '// &
              fmt_num((TAU_MACH_MIN - 0.5_wp)*per_tau)//' <= mach <= '// &
              fmt_num((TAU_MAX - 0.5_wp)*per_tau)//' on this lattice; change lbm.mach, or '// &
              knob//' (tau - 1/2 ~ 1/dx at a fixed mach), or set lbm.mach = 0 and use lbm.tau'
        return
      end if
      c%lbm%tau = tau
    end subroutine tau_from_mach
  end subroutine expand

  !> D_1 (cm), the pair's larger diameter: the larger of particles 1 and 2 (particle 1 when it
  !! is alone). The scale of the kissing thresholds, of D_r/D_1 and of /run d1; `c` has
  !! particles. The one definition every place reads (in spacings: pair_d1(c)/c%lbm%dx).
  pure real(wp) function pair_d1(c) result(d1)
    type(config_t), intent(in) :: c
    d1 = maxval(c%particles%diameter(1:min(2, c%particles%count)))
  end function pair_d1

  !> The largest diameter of all particles (cm): what a window (window.below, window.above in
  !! these) and a slab must hold; `c` has particles.
  pure real(wp) function largest_diameter(c) result(d)
    type(config_t), intent(in) :: c
    d = maxval(c%particles%diameter(1:c%particles%count))
  end function largest_diameter

  !> The longest the window may grow above the lowest free centre, in D_1 (docs/model.md §5):
  !! window.max_above when it is set (0: it never grows), and with the default -1 the window's
  !! length above plus the distance the velocity scale U of the scene (velocity_scale) covers
  !! in the run, U t/D_1, at most WINDOW_AUTO_CAP times window.above. Two disks settling side by
  !! side draw apart no faster than the faster of them falls, so a pair whose speeds stay within
  !! U never outruns a window that long, and a run given a longer run.t_end gets a longer limit;
  !! the cap keeps a run of days (or a velocity scale of a mistyped gravity) from asking for a
  !! window the memory check refuses, when the pair has long settled to a fixed distance.
  function window_max_above(c) result(above)
    type(config_t), intent(in) :: c
    real(wp) :: above
    real(wp) :: u, t_run, nu, reach
    character(len=:), allocatable :: source
    above = c%window%max_above
    if (above >= 0.0_wp) return
    call velocity_scale(c, u, source)
    t_run = c%run%t_end
    if (c%run%steps > 0) then
      ! E3: dt = nu_lb dx^2/nu, as lattice_from takes it
      nu = c%fluid%viscosity/c%fluid%density
      t_run = c%run%steps*(cs2*(c%lbm%tau - 0.5_wp)*c%lbm%dx**2/nu)
    end if
    ! at most the cap, compared without forming U t where it could overflow (a scene's
    ! velocity scale and length are only range-checked)
    reach = (WINDOW_AUTO_CAP - 1.0_wp)*c%window%above*largest_diameter(c)
    if (u <= reach/t_run) then
      above = c%window%above + u*t_run/largest_diameter(c)
    else
      above = WINDOW_AUTO_CAP*c%window%above
    end if
  end function window_max_above

  !> y (cm, absolute) of the lower end of the window at t = 0: window%below D_1 under the
  !! lowest free particle's centre. Particle positions stay absolute; node rows are counted
  !! from here.
  pure real(wp) function window_bottom(c) result(y)
    type(config_t), intent(in) :: c
    associate (p => c%particles)
      y = minval(p%y(1:p%count), mask=p%motion(1:p%count) == 'free') - &
          c%window%below*largest_diameter(c)
    end associate
  end function window_bottom

  !> The entry threshold of a kissing episode in lattice spacings as the input gives it:
  !! diagnostics.enter_cells, or collision.range + 1 when that is 0 (E10 holds a kissing pair
  !! just inside its range; the default entry is one spacing beyond it).
  pure real(wp) function kiss_enter_cells(c) result(cells)
    type(config_t), intent(in) :: c
    cells = c%diagnostics%enter_cells
    if (cells <= 0.0_wp) cells = c%collision%range + 1.0_wp
  end function kiss_enter_cells

  !> The gaps D_r (lattice spacings) at which a kissing episode of particles 1 and 2 starts
  !! and ends (docs/model.md §6): each the larger of its count of spacings and its fraction of D_1.
  pure subroutine kiss_thresholds(c, enter, release)
    type(config_t), intent(in) :: c
    real(wp), intent(out) :: enter, release
    real(wp) :: d1
    d1 = pair_d1(c)/c%lbm%dx
    enter = max(kiss_enter_cells(c), c%diagnostics%enter_d1*d1)
    release = max(c%diagnostics%release_cells, c%diagnostics%release_d1*d1)
  end subroutine kiss_thresholds

  !> How to make dx smaller (or, with `larger`, larger) in this scene: through
  !! lbm.cells_per_diameter when that sets dx (lbm.dx is then not used), else lbm.dx.
  function dx_knob(c, larger) result(s)
    type(config_t), intent(in) :: c
    logical, intent(in), optional :: larger
    character(len=:), allocatable :: s
    logical :: up
    up = .false.
    if (present(larger)) up = larger
    if (c%lbm%cells_per_diameter > 0.0_wp) then
      s = trim(merge('lower', 'raise', up))//' lbm.cells_per_diameter (it sets dx)'
    else
      s = 'make lbm.dx '//trim(merge('larger ', 'smaller', up))
    end if
  end function dx_knob

  !> The key(s) behind the largest of the velocities that make up the velocity scale of
  !! lattice_from (in cm/s): what a user changes to lower the Mach number.
  function velocity_scale_source(c) result(s)
    type(config_t), intent(in) :: c
    character(len=:), allocatable :: s
    real(wp) :: best
    call velocity_scale(c, best, s)
  end function velocity_scale_source

  !> The compressibility error class of an expected Mach number (docs/model.md §1, "Mach-aware
  !! set-up"): the weakly compressible scheme errs by O(Ma^2), named by the classes of
  !! MA2_CLASS_TOPS, e.g. 'noticeable (1e-2..5e-2)'.
  function compressibility_class(mach) result(s)
    real(wp), intent(in) :: mach
    character(len=:), allocatable :: s
    real(wp) :: m2
    m2 = mach**2
    if (m2 < MA2_CLASS_TOPS(1)) then
      s = 'negligible (< 1e-3)'
    else if (m2 < MA2_CLASS_TOPS(2)) then
      s = 'small (1e-3..1e-2)'
    else if (m2 < MA2_CLASS_TOPS(3)) then
      s = 'noticeable (1e-2..5e-2)'
    else
      s = 'large (> 5e-2)'
    end if
  end function compressibility_class

  !> The velocity scale of the scene in cm/s (docs/model.md §1, "Mach-aware set-up"): the
  !! largest of |inlet.velocity|, initial.velocity, the body-force Poiseuille peak
  !! |g| W^2/(8 nu), each particle's |(u, v)| and, for a free particle, its settling speed
  !! scale sqrt(pi D/2 |rho_p/rho_f - 1| g). lattice_from takes the same maximum in lattice
  !! units (u_scale_lb = best dt/dx); `s` names the key(s) behind the largest.
  subroutine velocity_scale(c, best, s)
    type(config_t), intent(in) :: c
    real(wp), intent(out) :: best
    character(len=:), allocatable, intent(out) :: s
    real(wp) :: u, nu
    integer :: k
    nu = c%fluid%viscosity/c%fluid%density
    best = abs(c%inlet%velocity)
    s = '&inlet velocity = '//fmt_num(c%inlet%velocity)//' cm/s'
    if (c%initial%velocity > best) then
      best = c%initial%velocity
      s = '&initial velocity = '//fmt_num(c%initial%velocity)//' cm/s'
    end if
    u = norm2(c%fluid%body_force)*c%domain%width**2/(8.0_wp*nu)
    if (u > best) then
      best = u
      s = '&fluid body_force (Poiseuille peak '//fmt_num(u)//' cm/s across &domain width)'
    end if
    associate (p => c%particles)
      do k = 1, p%count
        u = hypot(p%u(k), p%v(k))
        if (u > best) then
          best = u
          s = '&particles u('//itoa(k)//'), v('//itoa(k)//') of particle '//itoa(k)// &
              ' ('//fmt_num(u)//' cm/s)'
        end if
        if (p%motion(k) /= 'free') cycle
        u = sqrt(0.5_wp*pi*p%diameter(k)*abs(p%density(k)/c%fluid%density - 1.0_wp)*p%gravity)
        if (u > best) then
          best = u
          s = 'the settling speed scale '//fmt_num(u)//' cm/s of particle '//itoa(k)// &
              ' (&particles diameter('//itoa(k)//'), density('//itoa(k)//'), gravity)'
        end if
      end do
    end associate
  end subroutine velocity_scale

  !> Whether the scene names a pair, whose gap, kissing episodes and DKT pattern are followed
  !! (docs/model.md §6): a pair scene (&pair gamma > 0), a scene of two particles, or particles 1
  !! and 2 of a larger scene with diagnostics.pair. A suspension has none.
  pure logical function pair_named(c)
    type(config_t), intent(in) :: c
    pair_named = c%particles%count == 2 .or. (c%particles%count > 2 .and. &
                                              (c%pair%gamma > 0.0_wp .or. c%diagnostics%pair))
  end function pair_named

end module dkt_config_scene

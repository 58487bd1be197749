!> The conversion of a valid configuration to lattice units (E3, E4): spacing, time step,
!> relaxation rates, lattice size, run length, output schedules, velocity scale and the
!> particles, all in one pass (lattice_from).
module dkt_config_lattice
  use dkt_kinds, only: wp, cs2, pi
  use dkt_lattice, only: e3_heat_flux_rate
  use dkt_config_types, only: config_t
  use dkt_config_scene, only: window_bottom, pair_d1, largest_diameter, kiss_enter_cells, &
                              kiss_thresholds, dx_knob, velocity_scale_source, &
                              compressibility_class, pair_named, window_max_above
  implicit none
  private
  public :: lattice_from

  !> The particles of a scene in lattice units (docs/model.md §3-4), element k for particle k:
  !! everything the particle state is built from, converted once with the other units.
  type, public :: particles_lb_t
    real(wp), allocatable :: x(:), y(:)       !! centre; y from the lower end of the lattice
                                               !! (the window's at t = 0), positions absolute
    real(wp), allocatable :: r(:)             !! radius
    real(wp), allocatable :: u(:), v(:)       !! initial (or prescribed) velocity
    real(wp), allocatable :: omega(:)         !! initial (or prescribed) spin, per time step
    real(wp), allocatable :: density(:)       !! rho_p/rho_f: mass per lattice area (E8)
    real(wp) :: gravity = 0.0_wp              !! along -y, spacings per step^2 (E9)
    real(wp) :: stiffness = 0.0_wp            !! eps_p of E10 per unit depth, lattice units
    real(wp) :: stiffness_overlap = 0.0_wp    !! eps'_p of E10 per unit depth, lattice units
  end type particles_lb_t

  !> Lattice-unit parameters derived from a valid configuration (derive_lattice).
  type, public :: lattice_params_t
    real(wp) :: dx = 0.0_wp          !! cm, lattice spacing
    real(wp) :: dt = 0.0_wp          !! s, time step, diffusive scaling (E3)
    real(wp) :: tau = 0.0_wp         !! relaxation time, time steps
    real(wp) :: nu_lb = 0.0_wp       !! lattice kinematic viscosity (tau - 1/2)/3
    real(wp) :: s(0:8) = 0.0_wp      !! rates in moment order rho,e,eps,jx,qx,jy,qy,pxx,pxy (E3)
    integer :: nx = 0                !! cells across the channel
    integer :: ny = 0                !! cells along the channel at t = 0 (now: the domain's ny)
    integer :: steps = 0             !! time steps of the run
    integer :: field_every = 0       !! steps between field outputs; 0 = at the end only
    integer :: series_every = 1      !! steps between particle samples (>= 1)
    real(wp) :: force_lb(2) = 0.0_wp !! body force in lattice units
    real(wp) :: u_in_lb = 0.0_wp     !! inlet velocity in lattice units
    real(wp) :: u_init_lb = 0.0_wp   !! initial-flow amplitude in lattice units
    real(wp) :: u_scale_lb = 0.0_wp  !! largest expected lattice speed
    real(wp) :: mach = 0.0_wp        !! u_scale_lb / c_s
    real(wp) :: reynolds = 0.0_wp    !! U width / nu with U = u_scale_lb dx/dt (physical)
    real(wp) :: cells_per_diameter = 0.0_wp !! smallest used diameter / dx; 0 without particles
    logical :: particles_on = .false. !! the scene has particles (count > 0)
    type(particles_lb_t) :: particles !! particles 1..count in lattice units
    ! the scene's derived quantities, each computed here once (dkt_config_scene) for the
    ! modules that set up, report and write the run
    real(wp) :: d1 = 0.0_wp           !! cm, D_1 of the pair (pair_d1); 0 without particles
    real(wp) :: largest_diameter = 0.0_wp !! cm, of all particles; 0 without particles
    real(wp) :: window_bottom = 0.0_wp !! cm, the window's lower end at t = 0; 0 without window
    integer :: ny_max = 0             !! rows a growing window may reach (window.max_above); ny
                                      !! when it never grows
    integer :: grow_rows = 0          !! rows a growing window adds at a time; 0 when it never grows
    real(wp) :: kiss_enter_cells = 0.0_wp !! spacings, diagnostics.enter_cells as it acts
    real(wp) :: kiss_enter = 0.0_wp   !! spacings, the gap D_r that starts a kissing episode
    real(wp) :: kiss_release = 0.0_wp !! spacings, the gap D_r that ends it
    logical :: pair_on = .false.      !! particles 1 and 2 are a pair (pair_named)
    character(len=:), allocatable :: dx_knob         !! how to make dx smaller (advice)
    character(len=:), allocatable :: velocity_source !! the key(s) behind the velocity scale
    character(len=:), allocatable :: compressibility !! the O(Ma^2) error class of mach
  end type lattice_params_t

contains

  !> The lattice-unit parameters of a valid configuration `c`.
  function lattice_from(c) result(lp)
    type(config_t), intent(in) :: c
    type(lattice_params_t) :: lp
    real(wp) :: nu, s_nu, s_q, width_lb, u_g
    integer :: k, growths
    nu = c%fluid%viscosity/c%fluid%density ! cm^2/s
    lp%dx = c%lbm%dx
    lp%tau = c%lbm%tau
    lp%nu_lb = cs2*(c%lbm%tau - 0.5_wp)    ! E3 with s_nu = 1/tau
    lp%dt = lp%nu_lb*lp%dx**2/nu           ! E3: nu = nu_lb dx^2/dt (diffusive scaling)
    s_nu = 1.0_wp/c%lbm%tau
    if (c%lbm%collision == 'bgk') then
      lp%s = s_nu                          ! E4: BGK is MRT with every rate 1/tau
    else
      s_q = c%lbm%s_q
      ! s_q = 0 (the only value <= 0 that passes validation) asks for the E3 rule, which puts
      ! bounce-back walls exactly half-way between nodes.
      if (s_q <= 0.0_wp) s_q = e3_heat_flux_rate(s_nu)
      lp%s = [0.0_wp, c%lbm%s_e, c%lbm%s_eps, 0.0_wp, s_q, 0.0_wp, s_q, s_nu, s_nu]
    end if
    lp%nx = count_of(c%domain%width/lp%dx)
    lp%ny = count_of(c%domain%height/lp%dx)
    lp%steps = c%run%steps
    if (lp%steps == 0) lp%steps = count_of(c%run%t_end/lp%dt)
    lp%field_every = 0
    if (c%output%field_interval > 0.0_wp) &
      lp%field_every = max(1, count_of(c%output%field_interval/lp%dt))
    lp%series_every = max(1, count_of(c%output%series_interval/lp%dt))
    lp%force_lb = c%fluid%body_force*lp%dt**2/lp%dx
    lp%u_in_lb = c%inlet%velocity*lp%dt/lp%dx
    lp%u_init_lb = c%initial%velocity*lp%dt/lp%dx
    ! Body-force Poiseuille peak g W^2/(8 nu) in lattice units, W = nx.
    width_lb = real(lp%nx, wp)
    lp%u_scale_lb = max(abs(lp%u_in_lb), lp%u_init_lb, &
                        norm2(lp%force_lb)*width_lb**2/(8.0_wp*lp%nu_lb))
    ! particles: the given velocities, and for free ones the gravitational velocity scale
    ! sqrt(pi D/2 |rho_p/rho_f - 1| g) (of the order of the settling speed)
    do k = 1, c%particles%count
      associate (p => c%particles)
        u_g = 0.0_wp
        if (p%motion(k) == 'free') &
          u_g = sqrt(0.5_wp*pi*p%diameter(k)*abs(p%density(k)/c%fluid%density - 1.0_wp)* &
                     p%gravity)
        lp%u_scale_lb = max(lp%u_scale_lb, max(hypot(p%u(k), p%v(k)), u_g)*lp%dt/lp%dx)
      end associate
    end do
    lp%mach = lp%u_scale_lb/sqrt(cs2)
    lp%reynolds = (lp%u_scale_lb*lp%dx/lp%dt)*c%domain%width/nu
    lp%particles_on = c%particles%count > 0
    lp%cells_per_diameter = 0.0_wp
    if (lp%particles_on) &
      lp%cells_per_diameter = minval(c%particles%diameter(1:c%particles%count))/lp%dx
    call particles_to_lattice(c, lp%dx, lp%dt, lp%particles)
    if (lp%particles_on) then
      lp%d1 = pair_d1(c)
      lp%largest_diameter = largest_diameter(c)
      call kiss_thresholds(c, lp%kiss_enter, lp%kiss_release)
      lp%pair_on = pair_named(c)
    end if
    lp%ny_max = lp%ny
    if (c%window%enabled) then
      lp%window_bottom = window_bottom(c)
      ! docs/model.md §5: rows counted as the window's height is (dkt_config_scene expand)
      if (window_max_above(c) > 0.0_wp) then
        lp%ny_max = max(lp%ny, 3, nint((c%window%below + window_max_above(c))* &
                                       largest_diameter(c)/lp%dx))
        lp%grow_rows = max(1, nint(0.5_wp*c%window%above*largest_diameter(c)/lp%dx))
        ! a limit of its own (-1) ends on a whole growth, so that a run resumed with a later
        ! run.t_end, and so a farther limit, can resume from any window this one grew to
        if (c%window%max_above < 0.0_wp) then
          growths = (lp%ny_max - lp%ny + lp%grow_rows - 1)/lp%grow_rows
          lp%ny_max = lp%ny + growths*lp%grow_rows
        end if
      end if
    end if
    lp%kiss_enter_cells = kiss_enter_cells(c)
    lp%dx_knob = dx_knob(c)
    lp%velocity_source = velocity_scale_source(c)
    lp%compressibility = compressibility_class(lp%mach)
  contains
    pure integer function count_of(x)
      real(wp), intent(in) :: x
      count_of = nint(min(x, real(huge(1), wp) - 1.0_wp))
    end function count_of
  end function lattice_from

  !> Particles 1..count of `c` in lattice units of spacing `dx` (cm) and step `dt` (s):
  !! positions from the lattice's lower end (the window's at t = 0) over dx, radii over dx,
  !! velocities times dt/dx, spins times dt, densities over the fluid's, gravity times dt^2/dx,
  !! and the E10 stiffnesses eps_p in cm^2 s^2/(g/cm) and eps'_p in cm s^2/(g/cm) per unit
  !! depth.
  subroutine particles_to_lattice(c, dx, dt, lb)
    type(config_t), intent(in) :: c
    real(wp), intent(in) :: dx, dt
    type(particles_lb_t), intent(out) :: lb
    real(wp) :: y0, rho_f
    integer :: n
    n = c%particles%count
    if (n == 0) then ! a configuration built in code may leave its particle arrays unallocated
      allocate (lb%x(0), lb%y(0), lb%r(0), lb%u(0), lb%v(0), lb%omega(0), lb%density(0))
      return
    end if
    rho_f = c%fluid%density
    y0 = 0.0_wp
    if (c%window%enabled) y0 = window_bottom(c)
    associate (p => c%particles, col => c%collision)
      lb%x = p%x(1:n)/dx
      lb%y = (p%y(1:n) - y0)/dx
      lb%r = 0.5_wp*p%diameter(1:n)/dx
      lb%u = p%u(1:n)*dt/dx
      lb%v = p%v(1:n)*dt/dx
      lb%omega = p%omega(1:n)*dt
      lb%density = p%density(1:n)/rho_f
      lb%gravity = p%gravity*dt*dt/dx
      lb%stiffness = col%stiffness*rho_f/dt**2
      lb%stiffness_overlap = col%stiffness_overlap*rho_f*dx/dt**2
    end associate
  end subroutine particles_to_lattice

end module dkt_config_lattice

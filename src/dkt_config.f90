!> The input of dktlbm: namelist groups in physical units (cm, g, s), their defaults, the key
!> registry, validation in one routine, the conversion to lattice units, and the command line.
!>
!> Defaults are written in one place only, the type initialisers below. The registry built by
!> `build_registry` adds unit, range and meaning to each component; parsing, range checks,
!> `--print-defaults` and input/README.md (through tests/test_input_readme.py) all come from it.
module dkt_config
  use ieee_arithmetic, only: ieee_is_finite
  use dkt_kinds, only: wp, cs2, pi
  use dkt_mrt, only: e3_heat_flux_rate
  use dkt_store, only: PRECISION_NAMES
  use dkt_registry, only: registry_t, add_real, add_reals, add_integer, add_logical, &
                          add_string, add_choice, add_choices, find_key, check_key, value_text, &
                          allowed_text, origin_of, blame, quoted, fmt_real, fmt_num, itoa, &
                          append_text
  use dkt_namelist, only: parse_namelist, apply_override
  implicit none
  private
  public :: parse_command_line, parse_arguments, read_text_file, config_load, config_validate
  public :: derive_lattice, config_to_namelist, config_output_dir, print_help, window_bottom
  public :: kiss_enter_cells, kiss_thresholds, config_check_text, velocity_scale_source
  public :: dx_knob, pair_d1, largest_diameter, particles_allocate, velocity_scale
  public :: compressibility_class, build_registry

  !> &domain: the channel.
  type, public :: domain_cfg_t
    real(wp) :: width = 2.0_wp            !! cm, channel width (x)
    real(wp) :: height = 5.0_wp           !! cm, channel length (y)
    character(len=16) :: sides = 'wall'   !! boundary at x = 0 and x = width
    character(len=16) :: lower = 'wall'   !! boundary at the y = 0 end
    character(len=16) :: upper = 'wall'   !! boundary at the y = height end
  end type domain_cfg_t

  !> &fluid: the Newtonian fluid.
  type, public :: fluid_cfg_t
    real(wp) :: density = 1.0_wp          !! g/cm^3
    real(wp) :: viscosity = 0.01_wp       !! g/(cm s), dynamic viscosity mu
    real(wp) :: body_force(2) = 0.0_wp    !! cm/s^2, uniform acceleration on the fluid
  end type fluid_cfg_t

  !> &lbm: the numerical method.
  type, public :: lbm_cfg_t
    real(wp) :: dx = 0.004_wp             !! cm, lattice spacing
    real(wp) :: tau = 0.65_wp             !! relaxation time, in time steps
    character(len=8) :: collision = 'mrt' !! 'mrt' (E1) or 'bgk' (E4)
    real(wp) :: s_e = 1.1_wp              !! MRT energy rate (E3)
    real(wp) :: s_eps = 1.25_wp           !! MRT energy-square rate (E3)
    real(wp) :: s_q = 0.0_wp              !! MRT heat-flux rate; 0 = the E3 rule
    real(wp) :: cells_per_diameter = 0.0_wp !! > 0: dx from the smallest particle; 0 = use dx
    !> > 0: the target expected Mach number u_scale/c_s, which sets tau from dx and the scene's
    !! velocity scale (acoustic scaling, docs/model.md §1 "Mach-aware set-up"); 0 = use tau
    real(wp) :: mach = 0.0_wp
    !> 'in_place': one lattice, swept row by row; 'two_lattice': read one, write the other
    character(len=12) :: streaming = 'in_place'
    !> population storage: 'double' (8 bytes), 'single' (f_i - w_i in 4 bytes), or
    !! 'single_unshifted' (f_i in 4 bytes; only to measure what the shift buys)
    character(len=16) :: precision = 'double'
  end type lbm_cfg_t

  !> &inlet: a 'velocity' end of the channel.
  type, public :: inlet_cfg_t
    real(wp) :: velocity = 0.0_wp             !! cm/s, signed y-velocity (centreline if parabolic)
    character(len=16) :: profile = 'parabolic' !! 'uniform' or 'parabolic'
    real(wp) :: ramp_time = 0.0_wp            !! s, smooth ramp-up time of the inlet velocity
  end type inlet_cfg_t

  !> &initial: the flow at t = 0.
  type, public :: initial_cfg_t
    character(len=16) :: flow = 'rest'    !! 'rest' or 'taylor_green'
    real(wp) :: velocity = 0.0_wp         !! cm/s, amplitude of the initial flow
  end type initial_cfg_t

  !> The most particles a scene may hold: a checkpoint holds at most this many (dkt_checkpoint
  !! refuses a larger count as damaged), so a run with more could not be resumed.
  integer, parameter, public :: MAX_PARTICLES = 1000000

  !> &particles: rigid circular particles (docs/model.md §3), in physical units. Element k of each
  !! array belongs to particle k; only particles 1..count are used. config_load allocates the
  !! arrays to the size the input asks for (particle_slots), at least 1; particles_allocate
  !! sizes them for a configuration built in code.
  type, public :: particles_cfg_t
    integer :: count = 0                              !! number of particles, 0..MAX_PARTICLES
    real(wp), allocatable :: diameter(:)              !! cm
    real(wp), allocatable :: density(:)               !! g/cm^3
    real(wp), allocatable :: x(:)                     !! cm, centre across the channel
    real(wp), allocatable :: y(:)                     !! cm, centre along the channel
    real(wp), allocatable :: u(:)                     !! cm/s, initial (or prescribed) x-velocity
    real(wp), allocatable :: v(:)                     !! cm/s, initial (or prescribed) y-velocity
    real(wp), allocatable :: omega(:)                 !! 1/s, initial (or prescribed) spin
    character(len=16), allocatable :: motion(:)       !! 'free', 'fixed' or 'prescribed'
    real(wp) :: gravity = 980.0_wp                    !! cm/s^2, along -y on the particles (E9)
  end type particles_cfg_t

  !> &pair: the two particles of a DKT scene (docs/model.md §7), set by the diameter ratio and the
  !! initial distance. When gamma > 0 it writes particles 1 (the larger, D_1) and 2 (D_1/gamma)
  !! of &particles, both free, on the channel centreline.
  type, public :: pair_cfg_t
    real(wp) :: gamma = 0.0_wp              !! D_1/D_2 >= 1; 0 = no pair (&particles as given)
    real(wp) :: d1 = 0.2_wp                 !! cm, diameter of the larger particle
    real(wp) :: dh = 2.0_wp                 !! initial centre distance along y, in D_1
    character(len=16) :: upper = 'larger'   !! which particle starts above: 'larger', 'smaller'
    real(wp) :: y_upper = 15.0_wp           !! cm, y of the upper particle's centre
    real(wp) :: x_offset = 0.001_wp         !! cm, the upper particle off the centreline
    real(wp) :: density = 1.01_wp           !! g/cm^3, both particles
  end type pair_cfg_t

  !> &window: the computational window that follows the particles down an infinite channel
  !! (docs/model.md §5). Lengths in D_1, the largest diameter.
  type, public :: window_cfg_t
    logical :: enabled = .false.            !! follow the particles; domain height/ends derived
    real(wp) :: below = 10.0_wp             !! D_1 from the lowest centre down to the lower end
    real(wp) :: above = 15.0_wp             !! D_1 from the lowest centre up to the upper end
    real(wp) :: margin = 1.0_wp             !! D_1: a particle this close to the upper end ends
                                            !! the run (the pair separated beyond the window)
  end type window_cfg_t

  !> &diagnostics: the thresholds of a kissing episode (docs/model.md §6), each the larger of a
  !! number of lattice spacings and a fraction of D_1.
  type, public :: diagnostics_cfg_t
    real(wp) :: enter_cells = 0.0_wp        !! an episode starts at D_r <= this many spacings
                                            !! (0 = collision.range + 1, just outside E10) ..
    real(wp) :: enter_d1 = 0.05_wp          !! .. or this fraction of D_1, whichever is larger
    real(wp) :: release_cells = 4.0_wp      !! it ends at D_r > this many spacings ..
    real(wp) :: release_d1 = 0.25_wp        !! .. or this fraction of D_1, whichever is larger
  end type diagnostics_cfg_t

  !> &coupling: how the particles and the fluid exchange momentum.
  type, public :: coupling_cfg_t
    character(len=16) :: bounce_back = 'yu' !! 'halfway', 'yu' or 'bfl' (E6)
    character(len=16) :: momentum = 'paper' !! 'paper' or 'galilean' (E7)
    character(len=16) :: interior = 'solid' !! 'solid' or 'fluid' (nodes inside a particle)
  end type coupling_cfg_t

  !> &collision: the short-range repulsion of Wan & Turek between particles and walls.
  type, public :: collision_cfg_t
    real(wp) :: stiffness = 1.0e-7_wp         !! cm^3 s^2/g, eps_p of E10 (per unit depth)
    real(wp) :: stiffness_overlap = 1.0e-7_wp !! cm^2 s^2/g, eps'_p of E10 (per unit depth)
    real(wp) :: range = 1.0_wp                !! threshold xi of E10, in lattice spacings
    integer :: substeps = 1                   !! particle sub-steps per fluid step
  end type collision_cfg_t

  !> &run: length of the run and its guards.
  type, public :: run_cfg_t
    real(wp) :: t_end = 1.0_wp            !! s, simulated time (ignored when steps > 0)
    integer :: steps = 0                  !! time steps; 0 = from t_end
    real(wp) :: t_ref = 0.135526_wp       !! s, t* = t/t_ref; sqrt(18 cm / 980 cm/s^2)
                                          !! (docs/model.md §6)
    integer :: progress_every = 1000      !! steps between progress lines; 0 = none
    integer :: guard_every = 100          !! steps between NaN/Mach guards
    real(wp) :: mach_limit = 0.3_wp       !! largest allowed u/c_s
    real(wp) :: particle_speed_limit = 0.3_wp !! largest allowed particle |U| dt/dx
    integer :: checkpoint_every = 0       !! steps between checkpoints; 0 = none by steps
    real(wp) :: checkpoint_wall = 0.0_wp  !! s of wall time between checkpoints; 0 = none
    integer :: checkpoint_keep = 2        !! checkpoints kept (older ones are removed)
    real(wp) :: wall_limit = 0.0_wp       !! s of wall time after which the run checkpoints
                                          !! and stops; 0 = no limit
    real(wp) :: memory_limit = 0.0_wp     !! GiB a node may give the run; 0 = MemAvailable
    !> the keys a --restart may change on purpose, 'group.key' separated by commas or blanks
    !! (dkt_restart_input); '' = none beyond the run length, output and checkpoint keys
    character(len=1024) :: restart_changes = ''
  end type run_cfg_t

  !> &output: where and how often results are written.
  type, public :: output_cfg_t
    character(len=256) :: dir = ''        !! output directory; '' = runs/<namelist basename>
    real(wp) :: field_interval = 0.0_wp   !! s between field outputs; 0 = at the end only
    real(wp) :: series_interval = 0.0_wp  !! s between particle samples; 0 = every step
    logical :: overwrite = .false.        !! allow replacing an existing <dir>/<name>.h5
    integer :: compress = 0               !! deflate level of field snapshots, 0 = none
  end type output_cfg_t

  !> The whole input of a run.
  type, public :: config_t
    character(len=:), allocatable :: file !! namelist path as given
    character(len=:), allocatable :: name !! namelist basename without extension, e.g. 'case1'
    !> the input as read (namelist text), before &pair, &window and cells_per_diameter were
    !! turned into particles, domain and dx: reading it back gives the same configuration
    character(len=:), allocatable :: given
    type(domain_cfg_t) :: domain
    type(fluid_cfg_t) :: fluid
    type(lbm_cfg_t) :: lbm
    type(inlet_cfg_t) :: inlet
    type(initial_cfg_t) :: initial
    type(particles_cfg_t) :: particles
    type(pair_cfg_t) :: pair
    type(window_cfg_t) :: window
    type(diagnostics_cfg_t) :: diagnostics
    type(coupling_cfg_t) :: coupling
    type(collision_cfg_t) :: collision
    type(run_cfg_t) :: run
    type(output_cfg_t) :: output
  end type config_t

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
    integer :: ny = 0                !! cells along the channel
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
  end type lattice_params_t

  !> The command line: dktlbm FILE [--set g.k=v ...] [--check] [--print-defaults] [--help]
  !! [--version].
  type, public :: cli_t
    character(len=:), allocatable :: nml_file        !! the namelist file; '' if none was given
    character(len=512), allocatable :: overrides(:)  !! 'group.key=value', in the given order
    logical :: check = .false.
    logical :: print_defaults = .false.
    logical :: help = .false.
    logical :: version = .false.
    character(len=:), allocatable :: restart         !! checkpoint to resume from; '' = none
  end type cli_t

  character(len=*), parameter :: USAGE = 'usage: dktlbm FILE [--set group.key=value ...] '// &
                                 '[--restart CHECKPOINT] [--check] [--print-defaults] '// &
                                 '[--help] [--version]'
  character(len=*), parameter :: OPTIONS = '--set group.key=value, --set=group.key=value, '// &
                                 '--restart CHECKPOINT, --check, --print-defaults, --help, '// &
                                 '--version'
  character(len=*), parameter :: RESTART_NEEDS = 'option --restart needs a checkpoint file: '// &
                                 '--restart runs/case1/case1_chk_000010000.h5'
  character(len=*), parameter :: NL = new_line('a')
  real(wp), parameter :: WHOLE_TOL = 1.0e-6_wp !! how close width/dx must be to a whole number
  real(wp), parameter :: MAX_CELLS = 1.0e9_wp  !! more cells on one axis is surely a typing error
  real(wp), parameter :: MIN_CELLS_PER_D = 4.0_wp  !! fewer cells per diameter: refused
  real(wp), parameter :: GOOD_CELLS_PER_D = 8.0_wp !! fewer cells per diameter: a warning
  real(wp), parameter :: CONTACT_TOL = 1.0e-12_wp  !! relative round-off of a typed distance
  !> The measured stable region of a settling disk (docs/stability.md, from
  !! docs/stability_map.csv: tests/perf/stability_map.py, input/single.nml at 10 spacings per
  !! diameter): at each MAP_TAU, the largest lattice Reynolds number U dx/nu = Re_p/N (N spacings
  !! per diameter) below which every run of the grid finished stable. Beyond it, runs were
  !! stopped by the Mach guard (or not measured); U is the velocity scale of the input check.
  real(wp), parameter :: MAP_TAU(*) = [0.501_wp, 0.505_wp, 0.51_wp, 0.52_wp, 0.55_wp, 0.6_wp, &
                                       0.65_wp, 0.8_wp, 1.0_wp, 1.5_wp, 2.0_wp]
  real(wp), parameter :: MAP_RE_CELL(*) = [120.0_wp, 60.0_wp, 30.0_wp, 30.0_wp, 10.0_wp, 3.0_wp, &
                                           3.0_wp, 3.0_wp, 1.0_wp, 1.0_wp, 0.3_wp]
  !> more time steps than this is surely a unit or typing error (a day at 10^4 steps/s)
  real(wp), parameter :: MAX_STEPS = 1.0e9_wp
  !> a time step outside DT_MIN..DT_MAX s comes from a viscosity or density in the wrong units
  !! (no flow on a cm lattice needs it), and makes the lattice-unit forces under- or overflow
  real(wp), parameter :: DT_MIN = 1.0e-12_wp, DT_MAX = 1.0e6_wp
  real(wp), parameter :: TAU_MAX = 10.0_wp !! the largest lbm.tau, typed or set by lbm.mach
  !> the smallest tau lbm.mach may set: nu_lb >= 1/300, the 0.01 above 1/2 keeps clear of the
  !! stability edge of MRT near tau = 1/2 (the window test runs at 0.52; docs/model.md §1)
  real(wp), parameter :: TAU_MACH_MIN = 0.51_wp
  !> upper ends of the compressibility error classes in Ma^2 (docs/model.md §1, "Mach-aware
  !! set-up", ties them to the measured window table): negligible, small, noticeable; above
  !! the last one, large
  real(wp), parameter, public :: MA2_CLASS_TOPS(3) = [1.0e-3_wp, 1.0e-2_wp, 5.0e-2_wp]

contains

  !> Bind every input key to its component of `c`, with unit, range and meaning.
  subroutine build_registry(c, reg)
    type(config_t), intent(inout), target :: c
    type(registry_t), intent(out) :: reg
    character(len=*), parameter :: ENDS = 'wall periodic velocity outflow'
    integer :: j
    if (.not. allocated(c%particles%diameter)) &
      call particles_allocate(c%particles, max(1, c%particles%count))

    call add_real(reg, 'domain', 'width', c%domain%width, 'cm', &
                  'channel width (x, across the channel)', gt=0.0_wp)
    call add_real(reg, 'domain', 'height', c%domain%height, 'cm', &
                  'channel length (y, along the channel axis)', gt=0.0_wp)
    call add_choice(reg, 'domain', 'sides', c%domain%sides, 'wall periodic', &
                    'boundary at x = 0 and x = width')
    call add_choice(reg, 'domain', 'lower', c%domain%lower, ENDS, &
                    'boundary at the lower end y = 0 (velocity, outflow: E5)')
    call add_choice(reg, 'domain', 'upper', c%domain%upper, ENDS, &
                    'boundary at the upper end y = height; periodic only with lower periodic')

    call add_real(reg, 'fluid', 'density', c%fluid%density, 'g/cm^3', 'fluid density', gt=0.0_wp)
    call add_real(reg, 'fluid', 'viscosity', c%fluid%viscosity, 'g/(cm s)', &
                  'dynamic viscosity mu; the kinematic viscosity is mu/density', gt=0.0_wp)
    call add_reals(reg, 'fluid', 'body_force', c%fluid%body_force, 'cm/s^2', &
                   'uniform acceleration (x, y) on the fluid, for verification flows')

    call add_real(reg, 'lbm', 'dx', c%lbm%dx, 'cm', 'lattice spacing', gt=0.0_wp)
    call add_real(reg, 'lbm', 'tau', c%lbm%tau, '-', &
                  'relaxation time in time steps; sets nu_lb = (tau - 1/2)/3 and dt (E3); '// &
                  'not used when lbm.mach > 0', gt=0.5_wp, le=TAU_MAX)
    call add_choice(reg, 'lbm', 'collision', c%lbm%collision, 'mrt bgk', &
                    'collision model: multiple-relaxation-time (E1) or BGK (E4)')
    call add_real(reg, 'lbm', 's_e', c%lbm%s_e, '-', 'MRT rate of the energy moment (E3)', &
                  gt=0.0_wp, lt=2.0_wp)
    call add_real(reg, 'lbm', 's_eps', c%lbm%s_eps, '-', &
                  'MRT rate of the energy-square moment (E3)', gt=0.0_wp, lt=2.0_wp)
    call add_real(reg, 'lbm', 's_q', c%lbm%s_q, '-', 'MRT rate of the heat-flux moments; '// &
                  '0 = 8(2 - 1/tau)/(8 - 1/tau), which puts bounce-back walls half-way (E3)', &
                  gt=0.0_wp, lt=2.0_wp, zero_ok=.true.)
    call add_real(reg, 'lbm', 'cells_per_diameter', c%lbm%cells_per_diameter, '-', &
                  'lattice spacings across the smallest particle; > 0 sets dx = width/'// &
                  'nint(width n/D_min) in place of dx; 0 = use dx', ge=4.0_wp, le=1000.0_wp, &
                  zero_ok=.true.)
    call add_real(reg, 'lbm', 'mach', c%lbm%mach, '-', &
                  'target expected Mach number u_scale/c_s; > 0 sets tau = 1/2 + 3 mach c_s '// &
                  'nu/(u_scale dx) in place of tau (acoustic scaling: dt ~ dx), u_scale the '// &
                  'velocity scale of the report; 0 = use tau', gt=0.0_wp, le=1.0_wp, &
                  zero_ok=.true.)
    call add_choice(reg, 'lbm', 'precision', c%lbm%precision, PRECISION_NAMES, &
                    'population storage: 8 bytes, or 4 bytes holding f_i - w_i (computed in 8 '// &
                    'either way); single_unshifted stores f_i in 4 bytes, only to measure '// &
                    'what the shift buys, not for use')
    call add_choice(reg, 'lbm', 'streaming', c%lbm%streaming, 'in_place two_lattice', &
                    'one lattice swept in place, or two (read one, write the other); '// &
                    'the same results to the bit, in_place needs half the memory')

    call add_real(reg, 'inlet', 'velocity', c%inlet%velocity, 'cm/s', &
                  'signed y-velocity at a velocity end (centreline value if parabolic)')
    call add_choice(reg, 'inlet', 'profile', c%inlet%profile, 'uniform parabolic', &
                    'shape of the inlet velocity across the channel')
    call add_real(reg, 'inlet', 'ramp_time', c%inlet%ramp_time, 's', &
                  'the inlet velocity ramps up smoothly over this time; 0 = at once', ge=0.0_wp)

    call add_choice(reg, 'initial', 'flow', c%initial%flow, 'rest taylor_green', &
                    'flow at t = 0; taylor_green needs periodic sides and ends')
    call add_real(reg, 'initial', 'velocity', c%initial%velocity, 'cm/s', &
                  'amplitude of the initial flow', ge=0.0_wp)

    call add_integer(reg, 'particles', 'count', c%particles%count, '-', &
                     'number of particles; sets the size of each array, particle k uses '// &
                     'element k; at most what a checkpoint holds', &
                     ge=0, le=MAX_PARTICLES)
    call add_reals(reg, 'particles', 'diameter', c%particles%diameter, 'cm', &
                   'particle diameter', gt=0.0_wp)
    call add_reals(reg, 'particles', 'density', c%particles%density, 'g/cm^3', &
                   'particle density', gt=0.0_wp)
    call add_reals(reg, 'particles', 'x', c%particles%x, 'cm', &
                   'x of the centre at t = 0 (across the channel)')
    call add_reals(reg, 'particles', 'y', c%particles%y, 'cm', &
                   'y of the centre at t = 0 (along the channel)')
    call add_reals(reg, 'particles', 'u', c%particles%u, 'cm/s', &
                   'x-velocity at t = 0, kept if prescribed, 0 if fixed')
    call add_reals(reg, 'particles', 'v', c%particles%v, 'cm/s', &
                   'y-velocity at t = 0, kept if prescribed, 0 if fixed')
    call add_reals(reg, 'particles', 'omega', c%particles%omega, '1/s', &
                   'counter-clockwise angular velocity at t = 0, kept if prescribed, 0 if fixed')
    call add_choices(reg, 'particles', 'motion', c%particles%motion, 'free fixed prescribed', &
                     'free (moved by fluid and gravity, E8), fixed (at rest) or prescribed '// &
                     '(u, v, omega kept)')
    do j = 1, size(reg%keys)
      if (reg%keys(j)%group == 'particles' .and. reg%keys(j)%n > 0) reg%keys(j)%size_note = &
        ' (the particle arrays have particles.count elements, at least 1; raise '// &
        'particles.count for more particles, at most '//itoa(MAX_PARTICLES)//')'
    end do
    call add_real(reg, 'particles', 'gravity', c%particles%gravity, 'cm/s^2', &
                  'gravity on the particles, along -y; acts as weight minus buoyancy (E9)', &
                  ge=0.0_wp)

    call add_real(reg, 'pair', 'gamma', c%pair%gamma, '-', 'diameter ratio D_1/D_2 of a '// &
                  'DKT pair; > 0 sets particles 1 (D_1) and 2 (D_1/gamma); 0 = no pair', &
                  ge=1.0_wp, le=100.0_wp, zero_ok=.true.)
    call add_real(reg, 'pair', 'd1', c%pair%d1, 'cm', 'diameter D_1 of the larger particle', &
                  gt=0.0_wp)
    call add_real(reg, 'pair', 'dh', c%pair%dh, '-', &
                  'initial distance D_h of the centres along y, in D_1', gt=0.0_wp)
    call add_choice(reg, 'pair', 'upper', c%pair%upper, 'larger smaller', &
                    'which particle starts above the other (case1: larger, case2: smaller)')
    call add_real(reg, 'pair', 'y_upper', c%pair%y_upper, 'cm', &
                  'y of the upper particle''s centre at t = 0')
    call add_real(reg, 'pair', 'x_offset', c%pair%x_offset, 'cm', 'the upper particle '// &
                  'starts this far right of the centreline, breaking the mirror symmetry')
    call add_real(reg, 'pair', 'density', c%pair%density, 'g/cm^3', &
                  'density of both particles', gt=0.0_wp)

    call add_logical(reg, 'window', 'enabled', c%window%enabled, 'follow the lowest '// &
                     'particle down an infinite channel; sets the domain height and ends '// &
                     '(docs/model.md section 5)')
    call add_real(reg, 'window', 'below', c%window%below, '-', &
                  'window length below the lowest particle''s centre, in D_1', ge=1.0_wp)
    call add_real(reg, 'window', 'above', c%window%above, '-', &
                  'window length above the lowest particle''s centre, in D_1', ge=1.0_wp)
    call add_real(reg, 'window', 'margin', c%window%margin, '-', 'a particle that comes '// &
                  'this close (in D_1) to the upper end ends the run early', ge=0.0_wp)

    call add_real(reg, 'diagnostics', 'enter_cells', c%diagnostics%enter_cells, '-', &
                  'a kissing episode starts at D_r <= max(enter_cells dx, enter_d1 D_1); '// &
                  '0 = collision.range + 1', gt=0.0_wp, zero_ok=.true.)
    call add_real(reg, 'diagnostics', 'enter_d1', c%diagnostics%enter_d1, '-', &
                  'see enter_cells', ge=0.0_wp)
    call add_real(reg, 'diagnostics', 'release_cells', c%diagnostics%release_cells, '-', &
                  'an episode ends at D_r > max(release_cells dx, release_d1 D_1)', ge=0.0_wp)
    call add_real(reg, 'diagnostics', 'release_d1', c%diagnostics%release_d1, '-', &
                  'see release_cells', ge=0.0_wp)

    call add_choice(reg, 'coupling', 'bounce_back', c%coupling%bounce_back, 'halfway yu bfl', &
                    'bounce-back on the particle surface: half-way, Yu et al. or BFL (E6)')
    call add_choice(reg, 'coupling', 'momentum', c%coupling%momentum, 'paper galilean', &
                    'momentum exchange: the paper''s rule or Galilean-invariant (E7)')
    call add_choice(reg, 'coupling', 'interior', c%coupling%interior, 'solid fluid', &
                    'nodes inside a particle: reset to the rigid-body equilibrium, or fluid '// &
                    'bounced from both sides of the surface')

    call add_real(reg, 'collision', 'stiffness', c%collision%stiffness, 'cm^3 s^2/g', &
                  'eps_p of E10 for a gap below range (wall: eps_p/2, E11)', gt=0.0_wp)
    call add_real(reg, 'collision', 'stiffness_overlap', c%collision%stiffness_overlap, &
                  'cm^2 s^2/g', 'eps''_p of E10 for overlapping particles (wall: half, E11)', &
                  gt=0.0_wp)
    call add_real(reg, 'collision', 'range', c%collision%range, '-', &
                  'threshold xi of E10 in lattice spacings: repulsion acts below this gap', &
                  ge=0.0_wp)
    call add_integer(reg, 'collision', 'substeps', c%collision%substeps, '-', &
                     'particle sub-steps per fluid time step (for a stiff repulsion)', &
                     ge=1, le=1000)

    call add_real(reg, 'run', 't_end', c%run%t_end, 's', &
                  'simulated time (ignored when steps > 0)', gt=0.0_wp)
    call add_integer(reg, 'run', 'steps', c%run%steps, '-', &
                     'number of time steps; 0 = from t_end', ge=0, le=nint(MAX_STEPS))
    call add_real(reg, 'run', 't_ref', c%run%t_ref, 's', &
                  'time scale of t* = t/t_ref; default sqrt(18 cm / 980 cm/s^2)', gt=0.0_wp)
    call add_integer(reg, 'run', 'progress_every', c%run%progress_every, '-', &
                     'time steps between progress lines; 0 = none', ge=0)
    call add_integer(reg, 'run', 'guard_every', c%run%guard_every, '-', &
                     'time steps between the NaN and Mach-number guards', ge=1)
    call add_real(reg, 'run', 'mach_limit', c%run%mach_limit, '-', &
                  'largest allowed Mach number u/c_s before the run is stopped', &
                  gt=0.0_wp, le=1.0_wp)
    call add_real(reg, 'run', 'particle_speed_limit', c%run%particle_speed_limit, '-', &
                  'largest allowed particle speed in lattice spacings per time step, '// &
                  'checked every step; a faster particle stops the run', gt=0.0_wp, le=1.0_wp)
    call add_integer(reg, 'run', 'checkpoint_every', c%run%checkpoint_every, '-', &
                     'time steps between checkpoints; 0 = none by step count', ge=0)
    call add_real(reg, 'run', 'checkpoint_wall', c%run%checkpoint_wall, 's', &
                  'wall-clock time between checkpoints; 0 = none by wall time', ge=0.0_wp)
    call add_integer(reg, 'run', 'checkpoint_keep', c%run%checkpoint_keep, '-', &
                     'newest checkpoints kept; older ones are deleted', ge=1)
    call add_real(reg, 'run', 'wall_limit', c%run%wall_limit, 's', 'after this wall-clock '// &
                  'time the run writes a checkpoint and stops (exit 0); 0 = no limit', ge=0.0_wp)
    call add_real(reg, 'run', 'memory_limit', c%run%memory_limit, 'GiB', 'memory the ranks '// &
                  'of one node may use together; a run needing more is refused at start; '// &
                  '0 = MemAvailable of /proc/meminfo', ge=0.0_wp)
    call add_string(reg, 'run', 'restart_changes', c%run%restart_changes, 'keys a --restart '// &
                    'may change on purpose, as group.key separated by commas (e.g. '// &
                    '''pair.density, particles.gravity''); the changes are recorded in the run '// &
                    'file; empty = only the run length, output and checkpoint keys')

    call add_string(reg, 'output', 'dir', c%output%dir, &
                    'output directory; empty = runs/<namelist basename>')
    call add_real(reg, 'output', 'field_interval', c%output%field_interval, 's', &
                  'time between field outputs; 0 = fields at the end only', ge=0.0_wp)
    call add_real(reg, 'output', 'series_interval', c%output%series_interval, 's', &
                  'time between samples of the /particles series; 0 = every step', ge=0.0_wp)
    call add_logical(reg, 'output', 'overwrite', c%output%overwrite, &
                     'allow replacing an existing <dir>/<name>.h5')
    call add_integer(reg, 'output', 'compress', c%output%compress, '-', 'deflate (gzip) '// &
                     'level of the field snapshots, 1 fastest .. 9 smallest; 0 = uncompressed', &
                     ge=0, le=9)
  end subroutine build_registry

  !> Defaults, then the namelist `text`, then the `overrides` ('group.key=value'), then
  !! validation. `file` names the text in messages and gives cfg%name. On error `err` holds one
  !! message naming file (and line), group, key, value and what is allowed; '' if valid.
  !! `warnings`: what a valid configuration may get wrong (e.g. a coarsely resolved particle),
  !! one message a line, in the same form; '' when there is none or when `err` is set.
  !! `lp`: the lattice parameters of the valid configuration, derived here so that a start
  !! validates its input once (derive_lattice validates a configuration changed in code).
  subroutine config_load(cfg, text, file, overrides, err, warnings, lp)
    type(config_t), intent(out), target :: cfg !! intent(out): every component starts at default
    character(len=*), intent(in) :: text, file
    character(len=*), intent(in) :: overrides(:)
    character(len=:), allocatable, intent(out) :: err
    character(len=:), allocatable, intent(out), optional :: warnings
    type(lattice_params_t), intent(out), optional :: lp
    character(len=:), allocatable :: found
    type(registry_t) :: reg
    integer :: j
    if (present(warnings)) warnings = ''
    cfg%file = file
    cfg%name = basename(file)
    call particle_slots(text, file, overrides, j, err)
    if (len(err) > 0) return
    call particles_allocate(cfg%particles, j)
    call build_registry(cfg, reg)
    call parse_namelist(reg, text, file, err)
    if (len(err) > 0) return
    do j = 1, size(overrides)
      if (len_trim(overrides(j)) == 0) cycle
      call apply_override(reg, overrides(j), file, err)
      if (len(err) > 0) return
    end do
    do j = 1, size(reg%keys)
      call check_key(reg%keys(j), cfg%file, err)
      if (len(err) > 0) return
    end do
    call config_to_namelist(cfg, found)
    call move_alloc(found, cfg%given)
    call expand(cfg, reg, err)
    if (len(err) > 0) return
    call validate(cfg, reg, err, found)
    if (len(err) > 0) found = ''
    if (present(warnings)) warnings = found
    if (len(err) == 0 .and. present(lp)) lp = lattice_from(cfg)
  end subroutine config_load

  !> How many elements the particle arrays need (>= 1): particles.count when the input gives it
  !! (file or --set) above 0, else the highest element any &particles array key is given (a
  !! scene without particles may keep unused values); 2 at least
  !! for a pair scene (expand writes particles 1 and 2). A first read of the input that stores
  !! the scalars into a scratch configuration and only counts array elements.
  subroutine particle_slots(text, file, overrides, n, err)
    character(len=*), intent(in) :: text, file
    character(len=*), intent(in) :: overrides(:)
    integer, intent(out) :: n
    character(len=:), allocatable, intent(out) :: err
    type(config_t), target :: s
    type(registry_t) :: reg
    integer :: j, k
    n = 1
    call particles_allocate(s%particles, 1)
    call build_registry(s, reg)
    do j = 1, size(reg%keys)
      if (reg%keys(j)%group == 'particles' .and. reg%keys(j)%n > 0) &
        reg%keys(j)%open_to = MAX_PARTICLES
    end do
    ! An error stops this read where the second read will stop with the same message, whose
    ! index ranges then follow the count found up to there.
    call parse_namelist(reg, text, file, err)
    do j = 1, size(overrides)
      if (len(err) > 0) exit
      if (len_trim(overrides(j)) == 0) cycle
      call apply_override(reg, overrides(j), file, err)
    end do
    err = ''
    n = 0
    do j = 1, size(reg%keys)
      if (reg%keys(j)%group == 'particles') n = max(n, reg%keys(j)%top)
    end do
    ! a count out of range gets its message from the range check after the second read
    k = find_key(reg, 'particles', 'count')
    if (len(reg%keys(k)%origin) > 0 .and. s%particles%count > 0 .and. &
        s%particles%count <= MAX_PARTICLES) n = s%particles%count
    if (s%pair%gamma > 0.0_wp) n = max(n, 2)
    n = max(n, 1)
  end subroutine particle_slots

  !> Size the particle arrays of `p` to `n` elements: elements 1..min(n, old size) keep their
  !! values, the others take the defaults.
  subroutine particles_allocate(p, n)
    type(particles_cfg_t), intent(inout) :: p
    integer, intent(in) :: n
    call resize(p%diameter, 0.2_wp)
    call resize(p%density, 1.01_wp)
    call resize(p%x, 1.0_wp)
    call resize(p%y, 1.0_wp)
    call resize(p%u, 0.0_wp)
    call resize(p%v, 0.0_wp)
    call resize(p%omega, 0.0_wp)
    block
      character(len=16), allocatable :: t(:)
      allocate (t(n))
      t = 'free'
      if (allocated(p%motion)) t(1:min(n, size(p%motion))) = p%motion(1:min(n, size(p%motion)))
      call move_alloc(t, p%motion)
    end block
  contains
    subroutine resize(a, default)
      real(wp), allocatable, intent(inout) :: a(:)
      real(wp), intent(in) :: default
      real(wp), allocatable :: t(:)
      allocate (t(n))
      t = default
      if (allocated(a)) t(1:min(n, size(a))) = a(1:min(n, size(a)))
      call move_alloc(t, a)
    end subroutine resize
  end subroutine particles_allocate

  !> Validate a configuration built or changed in code ('' if valid); `warnings` as in
  !! config_load.
  subroutine config_validate(cfg, err, warnings)
    type(config_t), intent(in) :: cfg
    character(len=:), allocatable, intent(out) :: err
    character(len=:), allocatable, intent(out), optional :: warnings
    character(len=:), allocatable :: found
    type(config_t), target :: c
    type(registry_t) :: reg
    c = cfg
    if (.not. allocated(c%file)) c%file = ''
    call build_registry(c, reg)
    call validate(c, reg, err, found)
    if (len(err) > 0) found = ''
    if (present(warnings)) warnings = found
  end subroutine config_validate

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

  !> A scene file holds at least one namelist group: an empty file, or one of comments and
  !! blank lines only, would otherwise run the whole default scene without a word. (Text
  !! outside a group, and unknown groups, are the parser's to refuse.)
  subroutine config_check_text(text, file, err)
    character(len=*), intent(in) :: text, file
    character(len=:), allocatable, intent(out) :: err
    type(config_t), target :: defaults
    type(registry_t) :: reg
    character(len=:), allocatable :: groups, what
    integer :: a, b, j
    err = ''
    a = 1
    do while (a <= len(text))
      b = index(text(a:), NL)
      if (b == 0) then
        b = len(text) + 1
      else
        b = a + b - 1
      end if
      j = index(text(a:b - 1), '!')
      if (j == 0) j = b - a + 1
      ! anything but blanks, tabs and carriage returns before a comment is for the parser
      if (verify(text(a:a + j - 2), ' '//char(9)//char(13)) > 0) return
      a = b + 1
    end do
    call build_registry(defaults, reg)
    groups = '&'//reg%keys(1)%group
    do j = 2, size(reg%keys)
      if (reg%keys(j)%group /= reg%keys(j - 1)%group) groups = groups//', &'//reg%keys(j)%group
    end do
    what = 'holds only comments and blank lines'
    if (verify(text, ' '//char(9)//char(13)//NL) == 0) what = 'is empty'
    err = file//': '//what//'; a scene needs at least one '// &
          'namelist group, e.g. &domain width = 2.0 / (groups: '//groups//'); every key '// &
          'with its default: dktlbm --print-defaults; examples: input/*.nml'
  end subroutine config_check_text

  !> Every check of a configuration: each key's range or choices, then the rules that join
  !! keys. Messages name where the key was set (file:line or --set), else the file.
  !! `warnings`: newline-separated, '' if none; incomplete when `err` is set.
  !> The first pair k < m (smallest k, then smallest m, as a double loop finds it) of disks at
  !! (x, y) with diameters d whose centres are closer than the contact distance (d_k + d_m)/2
  !! (less CONTACT_TOL); k = m = 0 if none. A cell list makes it linear in the number of disks:
  !! the disks are sorted into square cells at least as wide as the largest diameter, so a disk
  !! can only touch disks of its own and the eight neighbouring cells. The cells are widened
  !! when the disks are spread far apart, so that there are at most about 4 n of them.
  subroutine first_overlap(x, y, d, k, m)
    real(wp), intent(in) :: x(:), y(:), d(:)
    integer, intent(out) :: k, m
    integer, allocatable :: cell(:), first(:), member(:), fill(:)
    real(wp) :: h, x0, y0, spread
    integer :: n, ncx, ncy, a, b, j, cx, cy, ix, iy, best
    n = size(x)
    k = 0
    m = 0
    if (n < 2) return
    x0 = minval(x)
    y0 = minval(y)
    spread = max(maxval(x) - x0, maxval(y) - y0)
    h = max(maxval(d), spread/(2.0_wp*sqrt(real(n, wp))), tiny(1.0_wp))
    ncx = int((maxval(x) - x0)/h) + 1
    ncy = int((maxval(y) - y0)/h) + 1
    allocate (cell(n), first(0:ncx*ncy), member(n), fill(0:ncx*ncy - 1))
    do a = 1, n
      cell(a) = min(int((x(a) - x0)/h), ncx - 1) + ncx*min(int((y(a) - y0)/h), ncy - 1)
    end do
    ! counting sort: the disks of cell j are member(first(j) + 1 : first(j + 1))
    first = 0
    do a = 1, n
      first(cell(a) + 1) = first(cell(a) + 1) + 1
    end do
    do j = 1, ncx*ncy
      first(j) = first(j) + first(j - 1)
    end do
    fill = first(0:ncx*ncy - 1)
    do a = 1, n
      fill(cell(a)) = fill(cell(a)) + 1
      member(fill(cell(a))) = a
    end do
    do a = 1, n
      cx = mod(cell(a), ncx)
      cy = cell(a)/ncx
      best = huge(best)
      do iy = max(cy - 1, 0), min(cy + 1, ncy - 1)
        do ix = max(cx - 1, 0), min(cx + 1, ncx - 1)
          do j = first(ix + ncx*iy) + 1, first(ix + ncx*iy + 1)
            b = member(j)
            if (b <= a .or. b >= best) cycle
            if (hypot(x(b) - x(a), y(b) - y(a)) < 0.5_wp*(d(a) + d(b))*(1.0_wp - CONTACT_TOL)) &
              best = b
          end do
        end do
      end do
      if (best < huge(best)) then
        k = a
        m = best
        return
      end if
    end do
  end subroutine first_overlap

  subroutine validate(c, reg, err, warnings)
    type(config_t), intent(in) :: c
    type(registry_t), intent(in) :: reg
    character(len=:), allocatable, intent(out) :: err
    character(len=:), allocatable, intent(out) :: warnings
    type(lattice_params_t) :: lp
    integer :: j
    integer :: few_cells, near_wall !! particles with too few cells, too near a wall (warned)
    integer, parameter :: WARN_EACH = 10 !! warnings naming a particle, then one line counting

    warnings = ''
    do j = 1, size(reg%keys)
      call check_key(reg%keys(j), c%file, err)
      if (len(err) > 0) return
    end do

    associate (d => c%domain)
      if ((d%lower == 'periodic') .neqv. (d%upper == 'periodic')) then
        err = from('domain.'//merge('lower', 'upper', d%lower == 'periodic')// &
                   ' domain.lower domain.upper')// &
              ': &domain lower = '//val('domain', 'lower')//' and upper = '// &
              val('domain', 'upper')//': a periodic channel needs both ends periodic; '// &
              'set lower and upper both to ''periodic'', or neither'
        return
      end if
      if (c%initial%flow == 'taylor_green' .and. &
          any([d%sides, d%lower, d%upper] /= 'periodic')) then
        err = from('initial.flow domain.sides domain.lower domain.upper')// &
              ': &initial flow = ''taylor_green'' needs a periodic '// &
              'domain, but &domain sides = '//val('domain', 'sides')//', lower = '// &
              val('domain', 'lower')//', upper = '//val('domain', 'upper')// &
              '; set all three to ''periodic'''
        return
      end if
      ! a particle would leave through a periodic side or end: not supported yet
      if (c%particles%count > 0 .and. any([d%sides, d%lower] == 'periodic')) then
        err = from('particles.count domain.sides domain.lower')//': &particles count = '// &
              val('particles', 'count')//' with &domain sides = '//val('domain', 'sides')// &
              ', lower = '//val('domain', 'lower')//': particles need walls or open ends; '// &
              'periodic sides or ends are for particle-free scenes'
        return
      end if
      call check_cells('width', 'nx', d%width)
      if (len(err) > 0) return
      call check_cells('height', 'ny', d%height)
      if (len(err) > 0) return
    end associate

    few_cells = 0
    near_wall = 0
    do j = 1, c%particles%count
      call check_particle(j)
      if (len(err) > 0) return
    end do
    ! a scene of many disks: the first WARN_EACH of each kind of warning, then a count
    if (few_cells > WARN_EACH) warnings = warnings//NL//from('lbm.dx particles.diameter')// &
                                          ': '//itoa(few_cells - WARN_EACH)//' more particles '// &
                                          'have fewer than '// &
                                          itoa(nint(GOOD_CELLS_PER_D))//' cells per diameter'
    if (near_wall > WARN_EACH) warnings = warnings//NL//from('particles.x particles.y lbm.dx')// &
                                          ': '//itoa(near_wall - WARN_EACH)//' more free '// &
                                          'particles start with '// &
                                          'their surface less than dx from a wall'
    ! a pair too close is the user's pair.dh, before it shows as an overlap of &particles
    if (c%pair%gamma > 0.0_wp) call check_pair()
    if (len(err) > 0) return
    call check_contacts()
    if (len(err) > 0) return
    if (c%window%enabled) call check_window()
    if (len(err) > 0) return

    ! the derived quantities, before anything that uses them: keys in range can still give
    ! dt = 0 or Infinity and NaN in every lattice-unit quantity after it. These two work with
    ! logarithms, so that no overflow happens (a checked build traps it) before they refuse.
    call check_time_step()
    if (len(err) > 0) return
    call check_steps()
    if (len(err) > 0) return
    lp = lattice_from(c)
    call check_prescribed_paths()
    if (len(err) > 0) return
    call check_velocity_scale()
    if (len(err) > 0) return
    call check_stability_map()
    if (c%particles%count >= 2) then
      call check_thresholds()
      if (len(err) > 0) return
      call check_duration()
    end if
  contains
    !> nu = viscosity/density and dt = nu_lb dx^2/nu (E3) are finite, and dt lies within
    !! DT_MIN..DT_MAX s: a viscosity or density far off (wrong units, a typing error) gives
    !! dt = 0 or Infinity and NaN in every lattice-unit quantity derived from it. In
    !! logarithms (both keys are > 0), so that computing them cannot overflow.
    subroutine check_time_step()
      real(wp) :: nu_log, dt_log
      character(len=:), allocatable :: head
      nu_log = log10(c%fluid%viscosity) - log10(c%fluid%density)
      dt_log = log10(cs2*(c%lbm%tau - 0.5_wp)) + 2.0_wp*log10(c%lbm%dx) - nu_log
      head = from('fluid.viscosity fluid.density lbm.tau lbm.dx lbm.cells_per_diameter')// &
             ': &fluid viscosity = '//val('fluid', 'viscosity')//' g/(cm s) and density = '// &
             val('fluid', 'density')//' g/cm^3 give '
      if (nu_log < log10(tiny(1.0_wp)) .or. nu_log > log10(huge(1.0_wp))) then
        err = head//'the kinematic viscosity nu = viscosity/density = '//power(nu_log)// &
              ' cm^2/s; allowed: a finite nu > 0 (water: viscosity = 0.01, density = 1.0); '// &
              'change &fluid viscosity or density'
      else if (dt_log < log10(DT_MIN) .or. dt_log > log10(DT_MAX)) then
        err = head//'nu = '//power(nu_log)//' cm^2/s, and with '//dx_text()// &
              ' and &lbm tau = '//val('lbm', 'tau')//' the time step dt = (tau - 1/2)/3 '// &
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
    end subroutine check_time_step

    !> t_end/dt rounds to 1..MAX_STEPS time steps (run.steps > 0 is range-checked as a key).
    !! dt is within DT_MIN..DT_MAX here; t_end/dt is compared in logarithms as well.
    subroutine check_steps()
      character(len=*), parameter :: STEP_KEYS = 'run.t_end lbm.tau lbm.dx '// &
                                     'lbm.cells_per_diameter fluid.viscosity fluid.density'
      real(wp) :: dt, n_log
      if (c%run%steps > 0) return
      dt = cs2*(c%lbm%tau - 0.5_wp)*c%lbm%dx**2/(c%fluid%viscosity/c%fluid%density)
      n_log = log10(c%run%t_end) - log10(dt)
      if (n_log < log10(0.5_wp)) then
        err = from(STEP_KEYS)//': &run t_end = '//val('run', 't_end')//' s gives 0 time '// &
              'steps: dt = '//fmt_num(dt)//' s (from '//dx_text()//', &lbm tau = '// &
              val('lbm', 'tau')//' and &fluid viscosity/density); allowed: t_end >= dt/2 = '// &
              fmt_num(0.5_wp*dt)//' s, or &run steps >= 1'
      else if (n_log > log10(MAX_STEPS)) then
        err = from(STEP_KEYS)//': &run t_end = '//val('run', 't_end')//' s gives '// &
              power(n_log)//' time steps of dt = '//fmt_num(dt)//' s (from '// &
              dx_text()//', &lbm tau = '//val('lbm', 'tau')//' and &fluid viscosity/'// &
              'density); allowed: at most '//itoa(nint(MAX_STEPS))//' steps, i.e. t_end <= '// &
              fmt_num(round6(MAX_STEPS*dt, down=.true.))//' s; make t_end smaller, or dt '// &
              'larger: raise lbm.tau, or '//dx_knob(c, larger=.true.)
      end if
    end subroutine check_steps

    !> 10^x as text: the value to six digits where a double holds it, else '1.0e<x>'
    function power(x) result(s)
      real(wp), intent(in) :: x
      character(len=:), allocatable :: s
      if (abs(x) < 300.0_wp) then
        s = fmt_num(round6(10.0_wp**x))
      else
        s = 'about 1.0e'//itoa(nint(x))
      end if
    end function power

    !> The velocity scale of the run is finite, and a prescribed particle (which moves at its
    !! velocity whatever the flow does, so the fluid next to it does too) is not faster than
    !! run.mach_limit allows: the guard would otherwise stop the run at its first check, and
    !! name a node instead of the particle.
    subroutine check_velocity_scale()
      real(wp) :: speed, u_max
      integer :: k
      if (.not. (ieee_is_finite(lp%u_scale_lb) .and. ieee_is_finite(lp%mach))) then
        err = src('density', 'fluid')//': the expected velocity scale is '// &
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
          err = from('particles.v particles.u run.particle_speed_limit lbm.dx lbm.tau')// &
                ': '//item('u', k, p%u(k))//', v('//itoa(k)//') = '//fmt_num(p%v(k))// &
                ': particle '//itoa(k)//' starts at '// &
                fmt_num(round6(speed*lp%dt/lp%dx))//' lattice spacings per step (dx = '// &
                fmt_num(lp%dx)//' cm, dt = '//fmt_num(lp%dt)//' s), above &run '// &
                'particle_speed_limit = '//val('run', 'particle_speed_limit')//'; allowed: '// &
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
          err = from('particles.v particles.u run.mach_limit lbm.dx lbm.tau')//': '// &
                item('u', k, p%u(k))//', v('//itoa(k)//') = '//fmt_num(p%v(k))// &
                ' with motion('//itoa(k)//') = ''prescribed'': particle '//itoa(k)// &
                ' moves at '//fmt_num(speed)//' cm/s, Mach '// &
                fmt_num(round6(speed*lp%dt/lp%dx/sqrt(cs2)))// &
                ' on this lattice (dx = '//fmt_num(lp%dx)//' cm, dt = '//fmt_num(lp%dt)// &
                ' s), above &run mach_limit = '//val('run', 'mach_limit')//'; allowed: a '// &
                'speed up to '//fmt_num(round6(u_max, down=.true.))//' cm/s; lower u('// &
                itoa(k)//') and v('//itoa(k)//'), or '//dx_knob(c)// &
                ' or lower &lbm tau (both shrink dt)'
          return
        end do
      end associate
    end subroutine check_velocity_scale

    !> A warning when a free particle's expected Reynolds number lies outside the measured
    !! stable region at this tau (MAP_TAU, MAP_RE_CELL; between two measured taus the smaller
    !! limit holds). The map's runs were single disks on the MRT model; the limit is in lattice
    !! units, Re_p/N = U dx/nu, so that a finer lattice raises the allowed Re_p with N.
    subroutine check_stability_map()
      real(wp) :: nu, u, re_p, re_max, n_d
      integer :: k, i
      character(len=:), allocatable :: where, advice
      nu = c%fluid%viscosity/c%fluid%density
      re_max = 0.0_wp
      where = 'outside the measured tau range '//fmt_num(MAP_TAU(1))//' to '// &
              fmt_num(MAP_TAU(size(MAP_TAU)))
      advice = 'choose lbm.tau within that range'
      do i = 1, size(MAP_TAU) - 1
        if (c%lbm%tau >= MAP_TAU(i) .and. c%lbm%tau <= MAP_TAU(i + 1)) then
          re_max = min(MAP_RE_CELL(i), MAP_RE_CELL(i + 1))
          where = ''
          advice = 'make dx smaller (Re_p/N falls with dx), or slow the particle'
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
          if (len(warnings) > 0) warnings = warnings//NL
          warnings = warnings//src('tau', 'lbm')//': &lbm tau = '//val('lbm', 'tau')// &
                     ' and particle '//itoa(k)//'''s expected Reynolds number Re_p = U D/nu = '// &
                     fmt_num(round6(re_p))//' (U = '//fmt_num(round6(u))//' cm/s, '// &
                     fmt_num(round6(n_d))//' spacings per diameter) lie '//where// &
                     ' (docs/stability.md, docs/stability_map.csv); the run may be stopped by '// &
                     'a guard; '//advice
          return
        end do
      end associate
    end subroutine check_stability_map

    !> A prescribed particle moves in a straight line at its constant velocity, so where it is
    !! at the run's end (steps x dt) is known now: its path must stay in the channel (a wall
    !! at least one radius away, an open end not passed by its centre) and not run into a fixed
    !! or another prescribed particle; neither can make way, and the run would go on with a
    !! particle outside the lattice or two solids in one place.
    subroutine check_prescribed_paths()
      real(wp) :: t_run, t_hit
      integer :: k, m
      character(len=:), allocatable :: head, what
      t_run = lp%steps*lp%dt
      associate (p => c%particles, d => c%domain)
        do k = 1, p%count
          if (p%motion(k) /= 'prescribed') cycle
          head = from('particles.v particles.u particles.x particles.y run.t_end run.steps')// &
                 ': &particles motion('//itoa(k)//') = ''prescribed'' with u('//itoa(k)// &
                 ') = '//fmt_num(p%u(k))//', v('//itoa(k)//') = '//fmt_num(p%v(k))// &
                 ' cm/s from (x, y) = ('//fmt_num(p%x(k))//', '//fmt_num(p%y(k))//') cm: '
          what = ''
          t_hit = huge(1.0_wp)
          call leaves(k, p%x(k), p%u(k), d%width, d%sides == 'wall', d%sides == 'wall', 'x', &
                      'side wall', 'side wall', what, t_hit)
          ! in a window the lattice follows the free particles; the run checks y as it goes
          if (.not. c%window%enabled) &
            call leaves(k, p%y(k), p%v(k), d%height, d%lower == 'wall', d%upper == 'wall', &
                        'y', 'lower end', 'upper end', what, t_hit)
          do m = 1, p%count
            if (m == k .or. p%motion(m) == 'free') cycle
            if (p%motion(m) == 'prescribed' .and. m < k) cycle ! the pair was checked from m
            call meets(k, m, what, t_hit)
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
    end subroutine check_prescribed_paths

    !> The first time in 0..t_run at which particle `k`, moving at `vel` from `pos` along
    !! one axis of `length`, touches a wall (`lo_wall`, `hi_wall`: at least one radius) or takes
    !! its centre past an open end; `what` and `t_hit` keep the earliest event.
    subroutine leaves(k, pos, vel, length, lo_wall, hi_wall, key, lo_name, hi_name, what, &
                      t_hit)
      integer, intent(in) :: k
      real(wp), intent(in) :: pos, vel, length
      logical, intent(in) :: lo_wall, hi_wall
      character(len=*), intent(in) :: key, lo_name, hi_name
      character(len=:), allocatable, intent(inout) :: what
      real(wp), intent(inout) :: t_hit
      real(wp) :: r, lo, hi, t, t_run
      t_run = lp%steps*lp%dt
      r = 0.5_wp*c%particles%diameter(k)
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
    subroutine meets(k, m, what, t_hit)
      integer, intent(in) :: k, m
      character(len=:), allocatable, intent(inout) :: what
      real(wp), intent(inout) :: t_hit
      real(wp) :: dx0, dy0, wx, wy, a, b, q, reach, disc, t
      associate (p => c%particles)
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

    !> '&lbm dx = ..' or '&lbm cells_per_diameter = .. (dx = .. cm)', whichever set dx
    function dx_text() result(s)
      character(len=:), allocatable :: s
      if (c%lbm%cells_per_diameter > 0.0_wp) then
        s = '&lbm cells_per_diameter = '//val('lbm', 'cells_per_diameter')//' (dx = '// &
            fmt_num(c%lbm%dx)//' cm)'
      else
        s = '&lbm dx = '//val('lbm', 'dx')
      end if
    end function dx_text

    function val(g, k) result(s)
      character(len=*), intent(in) :: g, k
      character(len=:), allocatable :: s
      s = value_text(reg%keys(find_key(reg, g, k)))
    end function val

    function src(k, g) result(s)
      character(len=*), intent(in) :: k, g
      character(len=:), allocatable :: s
      s = origin_of(reg, g, k, c%file)
    end function src

    !> The origin of a message on the keys 'group.key ...' (blame)
    function from(keys) result(s)
      character(len=*), intent(in) :: keys
      character(len=:), allocatable :: s
      s = blame(reg, keys, c%file)
    end function from

    !> length/dx must be a whole number (within WHOLE_TOL) of at least 3 cells: the lattice
    !! would otherwise silently change the channel's size, and a channel needs interior cells.
    subroutine check_cells(key, axis, length)
      character(len=*), intent(in) :: key, axis
      real(wp), intent(in) :: length
      real(wp) :: r
      character(len=:), allocatable :: both
      r = length/c%lbm%dx
      both = from('lbm.dx domain.'//key//' lbm.cells_per_diameter')//': &domain '//key//' = '// &
             val('domain', key)//' and &lbm dx = '//val('lbm', 'dx')//' give '
      if (r >= MAX_CELLS) then
        err = both//axis//' = '//key//'/dx = '//fmt_num(r)//' cells; allowed: fewer than '// &
              fmt_num(MAX_CELLS)//'; make dx larger'
      else if (nint(r) < 3) then
        err = both//axis//' = nint('//key//'/dx) = '//itoa(nint(r))//' cells; allowed: '// &
              axis//' >= 3; make dx smaller, e.g. dx = '//fmt_real(length/3.0_wp)
      else if (abs(r - anint(r)) > WHOLE_TOL) then
        ! the suggested dx is to be copied: all its digits, so that it gives whole cells
        err = both//key//'/dx = '//fmt_num(r)//' cells, not a whole number; choose dx = '// &
              key//'/n, e.g. dx = '//fmt_real(length/anint(r))//' ('//itoa(nint(r))//' cells)'
      end if
    end subroutine check_cells

    !> '&particles key(k) = value'
    function item(key, k, x) result(s)
      character(len=*), intent(in) :: key
      integer, intent(in) :: k
      real(wp), intent(in) :: x
      character(len=:), allocatable :: s
      s = '&particles '//key//'('//itoa(k)//') = '//fmt_num(x)
    end function item

    !> Particle k at t = 0: a fixed particle has no velocity, its centre lies in the channel
    !! at least one radius from every wall (touching a wall is an overlap: the bounce-back
    !! and the repulsion of E11 would start from a degenerate contact), and its diameter spans
    !! enough lattice cells for the boundary links of E6-E7 (docs/model.md §3).
    subroutine check_particle(k)
      integer, intent(in) :: k
      real(wp) :: cells
      character(len=:), allocatable :: key, both
      associate (p => c%particles, d => c%domain)
        if (p%motion(k) == 'fixed') then
          key = ''
          if (abs(p%omega(k)) > 0.0_wp) key = 'omega'
          if (abs(p%v(k)) > 0.0_wp) key = 'v'
          if (abs(p%u(k)) > 0.0_wp) key = 'u'
          if (len(key) > 0) then
            err = src(key, 'particles')//': &particles motion('//itoa(k)//') = ''fixed'' and '// &
                  item(key, k, merge(p%u(k), merge(p%v(k), p%omega(k), key == 'v'), key == 'u'))// &
                  ': a fixed particle does not move, so its velocity is not used; allowed: '// &
                  'u('//itoa(k)//') = v('//itoa(k)//') = omega('//itoa(k)//') = 0 with '// &
                  'motion = ''fixed''; set them to 0, or use motion = ''prescribed'' to keep '// &
                  'the particle moving at that velocity'
            return
          end if
        end if
        call check_position('x', k, p%x(k), 'width', d%width, d%sides == 'wall', &
                            d%sides == 'wall', '&domain sides = '//quoted(trim(d%sides)))
        if (len(err) > 0) return
        if (.not. c%window%enabled) then
          call check_position('y', k, p%y(k), 'height', d%height, d%lower == 'wall', &
                              d%upper == 'wall', '&domain lower = '//quoted(trim(d%lower))// &
                              ', upper = '//quoted(trim(d%upper)))
          if (len(err) > 0) return
        end if

        cells = p%diameter(k)/c%lbm%dx
        ! the message is built only when it is used: a scene may hold 10^5 particles
        if (cells < MIN_CELLS_PER_D - WHOLE_TOL .or. &
            (cells < GOOD_CELLS_PER_D - WHOLE_TOL .and. few_cells < WARN_EACH)) &
          both = from('lbm.dx particles.diameter lbm.cells_per_diameter')//': '// &
                 item('diameter', k, p%diameter(k))//' and &lbm dx = '//val('lbm', 'dx')// &
                 ' give '//fmt_num(cells)//' cells per diameter'
        if (cells < MIN_CELLS_PER_D - WHOLE_TOL) then
          err = both//'; allowed: diameter('//itoa(k)//')/dx >= '// &
                itoa(nint(MIN_CELLS_PER_D))//', i.e. dx <= diameter('//itoa(k)//')/'// &
                itoa(nint(MIN_CELLS_PER_D))//' = '// &
                fmt_num(p%diameter(k)/MIN_CELLS_PER_D)//' cm; make dx smaller'
        else if (cells < GOOD_CELLS_PER_D - WHOLE_TOL) then
          ! the first WARN_EACH such particles are named; the others are counted (below)
          few_cells = few_cells + 1
          if (few_cells <= WARN_EACH) then
            if (len(warnings) > 0) warnings = warnings//NL
            warnings = warnings//both//', fewer than '//itoa(nint(GOOD_CELLS_PER_D))// &
                       ': the force on particle '//itoa(k)//' and its motion will be '// &
                       'inaccurate; dx <= diameter('//itoa(k)//')/'// &
                       itoa(nint(GOOD_CELLS_PER_D))//' = '// &
                       fmt_num(p%diameter(k)/GOOD_CELLS_PER_D)//' cm gives '// &
                       itoa(nint(GOOD_CELLS_PER_D))
          end if
        end if
        call check_wall_gap(k)
      end associate
    end subroutine check_particle

    !> A warning for a free particle whose surface starts less than one lattice spacing from a
    !! wall. Measured (docs/stability.md): input/single.nml at 10 spacings per diameter with the
    !! surface 0.49 and 0.5 spacings from the side wall was stopped by the Mach guard after
    !! 370-420 steps in the gap's flow, at 0.2, 0.75 and 1 spacing it ran through.
    subroutine check_wall_gap(k)
      integer, intent(in) :: k
      real(wp) :: gap(4), r
      logical :: wall(4)
      character(len=*), parameter :: NAMES(4) = &
                                     [character(len=12) :: 'x = 0', 'x = width', 'y = 0', &
                                                            'y = height']
      integer :: j
      associate (p => c%particles, d => c%domain)
        if (p%motion(k) /= 'free') return
        r = 0.5_wp*p%diameter(k)
        gap = [p%x(k) - r, d%width - p%x(k) - r, p%y(k) - r, d%height - p%y(k) - r]
        wall = [d%sides == 'wall', d%sides == 'wall', &
                d%lower == 'wall' .and. .not. c%window%enabled, &
                d%upper == 'wall' .and. .not. c%window%enabled]
        do j = 1, size(gap)
          if (.not. wall(j) .or. gap(j) >= c%lbm%dx*(1.0_wp - CONTACT_TOL)) cycle
          near_wall = near_wall + 1
          if (near_wall > WARN_EACH) return
          if (len(warnings) > 0) warnings = warnings//NL
          warnings = warnings//from('particles.x particles.y lbm.dx')//': particle '// &
                     itoa(k)//' starts with its surface '//fmt_num(round6(gap(j)/c%lbm%dx))// &
                     ' lattice spacings from the wall at '//trim(NAMES(j))//' (dx = '// &
                     fmt_num(c%lbm%dx)//' cm); a disk started half a spacing from a wall '// &
                     'was measured to be stopped by the Mach guard in the gap''s flow '// &
                     '(docs/stability.md); start it at least dx from the wall'
          return
        end do
      end associate
    end subroutine check_wall_gap

    !> Coordinate `key` = `pos` of the centre of particle k within 0..length (`dim`); a wall
    !! at the low (`lo_wall`) or high end (`hi_wall`) must be more than one radius away.
    subroutine check_position(key, k, pos, dim, length, lo_wall, hi_wall, ends)
      character(len=*), intent(in) :: key, dim, ends
      integer, intent(in) :: k
      real(wp), intent(in) :: pos, length
      logical, intent(in) :: lo_wall, hi_wall
      real(wp) :: r, lo, hi
      character(len=:), allocatable :: head, allowed, what
      r = 0.5_wp*c%particles%diameter(k)
      lo = merge(r, 0.0_wp, lo_wall)
      hi = merge(length - r, length, hi_wall)
      if ((pos > lo .or. (.not. lo_wall .and. pos >= lo)) .and. &
          (pos < hi .or. (.not. hi_wall .and. pos <= hi))) return
      head = from('particles.'//key//' particles.diameter domain.'//dim//' domain.sides '// &
                  'domain.lower domain.upper')//': '//item(key, k, pos)//' with '// &
             item('diameter', k, c%particles%diameter(k))//', &domain '//dim//' = '// &
             val('domain', dim)//' and '//ends//': '
      allowed = fmt_num(lo)//trim(merge(' < ', ' <=', lo_wall))//' '//key//'('//itoa(k)// &
                ')'//trim(merge(' < ', ' <=', hi_wall))//' '//fmt_num(hi)
      if (lo >= hi) then
        err = head//'particle '//itoa(k)//' is not narrower than the channel between its '// &
              'walls; allowed: diameter('//itoa(k)//') < '//dim//' = '//val('domain', dim)
        return
      else if (pos < 0.0_wp .or. pos > length) then
        what = 'the centre of particle '//itoa(k)//' is outside the channel, 0 <= '//key// &
               ' <= '//fmt_num(length)
      else if (pos <= lo) then
        what = 'particle '//itoa(k)//' overlaps the wall at '//key//' = 0 at t = 0 (gap '// &
               key//' - diameter/2 = '//fmt_num(pos - r)//' cm; touching counts as overlap)'
      else
        what = 'particle '//itoa(k)//' overlaps the wall at '//key//' = '//fmt_num(length)// &
               ' at t = 0 (gap '//dim//' - '//key//' - diameter/2 = '// &
               fmt_num(length - pos - r)//' cm; touching counts as overlap)'
      end if
      err = head//what//'; allowed: '//allowed//' (the centre at least one radius from a wall)'
    end subroutine check_position

    !> No two particles overlap at t = 0: the distance of their centres is at least the sum of
    !! their radii (E10 would otherwise start with its overlap branch). Touching is allowed, to
    !! within round-off (CONTACT_TOL), so that centres typed exactly one contact distance apart
    !! are accepted.
    subroutine check_contacts()
      real(wp) :: gx, gy, dist, contact
      integer :: k, m
      associate (p => c%particles)
        call first_overlap(p%x(1:p%count), p%y(1:p%count), p%diameter(1:p%count), k, m)
        if (k == 0) return
        gx = p%x(m) - p%x(k)
        gy = p%y(m) - p%y(k)
        dist = hypot(gx, gy)
        contact = 0.5_wp*(p%diameter(k) + p%diameter(m))
        err = from('particles.y particles.x particles.diameter')// &
              ': &particles: particles '//itoa(k)//' and '//itoa(m)//' overlap at t = 0: '// &
              pair('x', k, m)//', '//pair('y', k, m)//', '// &
              pair('diameter', k, m)//': the distance of the centres '//fmt_num(dist)// &
              ' cm is less than the contact distance (diameter('//itoa(k)// &
              ') + diameter('//itoa(m)//'))/2 = '//fmt_num(contact)//' cm; allowed: '// &
              'a distance of at least '//fmt_num(contact)//' cm; move them apart'
      end associate
    end subroutine check_contacts

    !> D_h leaves a gap wider than the contact range of E10 between the pair's surfaces: a
    !! pair that starts inside the range starts in contact, and drafting is never seen.
    subroutine check_pair()
      real(wp) :: contact, dh_min
      associate (q => c%pair)
        contact = 0.5_wp*q%d1*(1.0_wp + 1.0_wp/q%gamma) + c%collision%range*c%lbm%dx
        dh_min = contact/q%d1
        if (q%dh*q%d1 <= contact*(1.0_wp + CONTACT_TOL)) &
          err = from('pair.dh pair.d1 pair.gamma collision.range lbm.dx '// &
                     'lbm.cells_per_diameter')//': &pair dh = '//val('pair', 'dh')// &
                ' gives D_h = '// &
                fmt_num(q%dh*q%d1)//' cm with d1 = '//val('pair', 'd1')//', gamma = '// &
                val('pair', 'gamma')//': the pair starts within the contact distance '// &
                '(D_1 + D_2)/2 + collision.range dx = '//fmt_num(contact)//' cm; allowed: '// &
                'dh > '//fmt_num(round_up(dh_min))
      end associate
    end subroutine check_pair

    !> Every particle lies inside the window at t = 0, below its upper end by the margin.
    subroutine check_window()
      real(wp) :: y_lo, y_hi, top, d1, need
      integer :: k
      associate (p => c%particles, win => c%window)
        d1 = largest_diameter(c)
        y_lo = window_bottom(c)
        y_hi = y_lo + c%domain%height
        do k = 1, p%count
          top = p%y(k) + 0.5_wp*p%diameter(k) + win%margin*d1
          if (top > y_hi .or. p%y(k) - 0.5_wp*p%diameter(k) < y_lo) then
            need = (top - minval(p%y(1:p%count), mask=p%motion(1:p%count) == 'free'))/d1
            err = from('window.above window.margin particles.y particles.diameter pair.dh '// &
                       'pair.y_upper pair.d1 pair.gamma')//': &window above = '// &
                  val('window', 'above')// &
                  ' D_1 (D_1 = '//fmt_num(d1)//' cm) cannot hold the particles: the window '// &
                  'spans y = '//fmt_num(y_lo)//' .. '//fmt_num(y_hi)//' cm, but particle '// &
                  itoa(k)//' (y = '//fmt_num(p%y(k))//', diameter '// &
                  fmt_num(p%diameter(k))//') with the margin of '//val('window', 'margin')// &
                  ' D_1 reaches '//fmt_num(top)//' cm; allowed: above >= '// &
                  fmt_num(round_up(need))
            return
          end if
        end do
      end associate
    end subroutine check_window

    !> The episode thresholds of &diagnostics (in spacings) leave a hysteresis: release > enter.
    subroutine check_thresholds()
      real(wp) :: d1, enter, release
      d1 = pair_d1(c)/c%lbm%dx
      call kiss_thresholds(c, enter, release)
      associate (g => c%diagnostics)
        if (release <= enter) &
          err = from('diagnostics.release_cells diagnostics.release_d1 '// &
                     'diagnostics.enter_cells diagnostics.enter_d1 collision.range lbm.dx '// &
                     'lbm.cells_per_diameter')//': &diagnostics release_cells = '// &
                val('diagnostics', 'release_cells')//' and release_d1 = '// &
                val('diagnostics', 'release_d1')//' give a release gap of '// &
                fmt_num(release)//' spacings, not above the entry gap of '// &
                fmt_num(enter)//' spacings from enter_cells = '// &
                val('diagnostics', 'enter_cells')//' and enter_d1 = '// &
                val('diagnostics', 'enter_d1')//' (D_1 = '//fmt_num(d1)// &
                ' spacings); allowed: release_cells > '//fmt_num(enter)//' or release_d1 > '// &
                fmt_num(enter/d1)//', or a smaller entry gap (enter_cells, enter_d1)'
      end associate
    end subroutine check_thresholds

    !> A warning when the run looks too short to see the pair kiss and separate: the initial
    !! surface gap closed at a tenth of the settling-velocity scale u_g = sqrt(pi D_1/2
    !! (rho_p/rho_f - 1) g) of the larger particle (drafting in case0 closes at about that
    !! rate), plus five D_1/u_g for the kiss and the separation. A rough estimate, on purpose.
    subroutine check_duration()
      real(wp) :: gap, u_g, t_need, t_run
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
        if (len(warnings) > 0) warnings = warnings//NL
        warnings = warnings//src('t_end', 'run')//': &run t_end = '//fmt_num(t_run)// &
                   ' s may be too short to classify the DKT pattern of particles 1 and 2: '// &
                   'closing their gap of '//fmt_num(gap)//' cm at a tenth of the settling '// &
                   'velocity scale and separating takes about '//fmt_num(t_need)// &
                   ' s; a pattern ''never'' or ''once'' may only mean the run stopped early'
      end associate
    end subroutine check_duration

    !> x to six significant digits, for derived values in messages (no round-off tail);
    !! rounded towards zero with `down` (a bound that must still hold)
    pure real(wp) function round6(x, down)
      real(wp), intent(in) :: x
      logical, intent(in), optional :: down
      real(wp) :: unit, q
      integer :: e
      round6 = x
      if (abs(x) <= 0.0_wp .or. .not. ieee_is_finite(x)) return
      e = floor(log10(abs(x))) - 5
      unit = 10.0_wp**abs(e)
      ! divide or multiply by an exact power of ten, never by its inexact reciprocal
      q = merge(x/unit, x*unit, e >= 0)
      q = anint(q)
      if (present(down)) then
        if (down) q = aint(merge(x/unit, x*unit, e >= 0))
      end if
      round6 = merge(q*unit, q/unit, e >= 0)
    end function round6

    !> x rounded up to three decimals (a bound printed without round-off noise that still
    !! holds: 21.499999999999993 -> 21.5)
    pure real(wp) function round_up(x)
      real(wp), intent(in) :: x
      round_up = ceiling(x*1000.0_wp - 1.0e-6_wp)/1000.0_wp
    end function round_up

    !> 'key(k) = a and key(m) = b'
    function pair(key, k, m) result(s)
      character(len=*), intent(in) :: key
      integer, intent(in) :: k, m
      character(len=:), allocatable :: s
      real(wp) :: a, b
      select case (key)
      case ('x')
        a = c%particles%x(k); b = c%particles%x(m)
      case ('y')
        a = c%particles%y(k); b = c%particles%y(m)
      case default
        a = c%particles%diameter(k); b = c%particles%diameter(m)
      end select
      s = key//'('//itoa(k)//') = '//fmt_num(a)//' and '//key//'('//itoa(m)//') = '//fmt_num(b)
    end function pair
  end subroutine validate

  !> The lattice-unit parameters of a configuration (E3, E4); `cfg` must be valid.
  !! `warnings` as in config_load.
  subroutine derive_lattice(cfg, lp, err, warnings)
    type(config_t), intent(in) :: cfg
    type(lattice_params_t), intent(out) :: lp
    character(len=:), allocatable, intent(out) :: err
    character(len=:), allocatable, intent(out), optional :: warnings
    call config_validate(cfg, err, warnings)
    if (len(err) == 0) lp = lattice_from(cfg)
  end subroutine derive_lattice

  function lattice_from(c) result(lp)
    type(config_t), intent(in) :: c
    type(lattice_params_t) :: lp
    real(wp) :: nu, s_nu, s_q, width_lb, u_g
    integer :: k
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

  !> The whole configuration as namelist text that config_load reads back: one key per line,
  !! each with '! [unit] default: ..; allowed: ..; meaning'. For --print-defaults and the
  !! output file.
  subroutine config_to_namelist(cfg, text)
    type(config_t), intent(in) :: cfg
    character(len=:), allocatable, intent(out) :: text
    type(config_t), target :: c, defaults ! `defaults` keeps its initial (default) values
    type(registry_t) :: reg, dreg
    character(len=:), allocatable :: line
    integer :: j
    c = cfg
    call build_registry(c, reg)
    ! the default column lists as many elements as the value column
    call particles_allocate(defaults%particles, size(c%particles%diameter))
    call build_registry(defaults, dreg)
    text = '! dktlbm input: every key with its value. Units cm, g, s. Each key''s comment:'//NL// &
           '! [unit] default: ..; allowed: ..; meaning. Reference: input/README.md.'//NL
    do j = 1, size(reg%keys)
      associate (k => reg%keys(j))
        if (j == 1) then
          text = text//'&'//k%group//NL
        else if (k%group /= reg%keys(j - 1)%group) then
          text = text//'/'//NL//'&'//k%group//NL
        end if
        line = '  '//k%name//' = '//value_text(k)
        line = line//repeat(' ', max(1, 34 - len(line)))
        text = text//line//'! ['//k%unit//'] default: '//value_text(dreg%keys(j))// &
               '; allowed: '//allowed_text(k)//'; '//k%meaning//NL
      end associate
    end do
    text = text//'/'//NL
  end subroutine config_to_namelist

  !> The output directory: output%dir, or runs/<name> when it is empty.
  function config_output_dir(cfg) result(dir)
    type(config_t), intent(in) :: cfg
    character(len=:), allocatable :: dir
    dir = trim(cfg%output%dir)
    if (len(dir) == 0) dir = 'runs/'//cfg%name
  end function config_output_dir

  ! ---------------------------------------------------------------- command line and files

  !> Read the command line of the program into `cli` (see parse_arguments).
  subroutine parse_command_line(cli, err)
    type(cli_t), intent(out) :: cli
    character(len=:), allocatable, intent(out) :: err
    integer :: j, n, length, longest
    n = command_argument_count()
    longest = 1
    do j = 1, n
      call get_command_argument(j, length=length)
      longest = max(longest, length)
    end do
    block
      character(len=longest) :: args(n)
      do j = 1, n
        call get_command_argument(j, args(j))
      end do
      call parse_arguments(args, cli, err)
    end block
  end subroutine parse_command_line

  !> Interpret the arguments `args` (without the program name):
  !! FILE [--set g.k=v | --set=g.k=v ...] [--check] [--print-defaults] [--help] [--version].
  !! A FILE is needed unless --help, --version or --print-defaults is given.
  subroutine parse_arguments(args, cli, err)
    character(len=*), intent(in) :: args(:)
    type(cli_t), intent(out) :: cli
    character(len=:), allocatable, intent(out) :: err
    character(len=:), allocatable :: arg
    integer :: j
    err = ''
    cli%nml_file = ''
    cli%restart = ''
    allocate (cli%overrides(0))
    j = 0
    do while (j < size(args))
      j = j + 1
      arg = trim(args(j))
      select case (arg)
      case ('--set')
        if (j == size(args)) then
          err = 'option --set needs a value: --set group.key=value, e.g. --set lbm.tau=0.7'
          return
        end if
        j = j + 1
        call add_override(trim(args(j)))
      case ('--restart')
        if (j == size(args)) then
          err = RESTART_NEEDS
          return
        end if
        j = j + 1
        cli%restart = trim(args(j))
        ! an empty value (--restart '') would otherwise start a fresh run
        if (len(cli%restart) == 0) err = RESTART_NEEDS
      case ('--check')
        cli%check = .true.
      case ('--print-defaults')
        cli%print_defaults = .true.
      case ('--help', '-h')
        cli%help = .true.
      case ('--version')
        cli%version = .true.
      case default
        if (index(arg, '--set=') == 1) then
          call add_override(arg(7:))
        else if (index(arg, '--restart=') == 1) then
          cli%restart = arg(11:)
          if (len(cli%restart) == 0) err = RESTART_NEEDS
        else if (index(arg, '-') == 1 .and. len(arg) > 1) then
          err = 'unknown option '''//arg//'''; options: '//OPTIONS//NL//USAGE
        else if (len(cli%nml_file) > 0) then
          err = 'more than one namelist file: '''//cli%nml_file//''' and '''//arg//''''// &
                NL//USAGE
        else
          cli%nml_file = arg
        end if
      end select
      if (len(err) > 0) return
    end do
    if (len(cli%nml_file) == 0 .and. .not. (cli%help .or. cli%version .or. cli%print_defaults)) &
      err = 'no namelist file given'//NL//USAGE//NL//'see dktlbm --help'
  contains
    subroutine add_override(spec)
      character(len=*), intent(in) :: spec
      if (len(spec) > len(cli%overrides)) then
        err = 'option --set '//spec(:40)//'... is longer than '//itoa(len(cli%overrides))// &
              ' characters'
      else if (index(spec, '=') == 0 .or. index(spec, '.') == 0) then
        err = 'option --set '//spec//': expected --set group.key=value, e.g. --set lbm.tau=0.7'
      else
        cli%overrides = [character(len=len(cli%overrides)) :: cli%overrides, spec]
      end if
    end subroutine add_override
  end subroutine parse_arguments

  !> Read the file `path` whole into `text`, newlines kept.
  subroutine read_text_file(path, text, err)
    character(len=*), intent(in) :: path
    character(len=:), allocatable, intent(out) :: text
    character(len=:), allocatable, intent(out) :: err
    character(len=256) :: msg
    logical :: exists
    integer :: unit, ios, nbytes
    err = ''
    text = ''
    inquire (file=path, exist=exists)
    if (.not. exists) then
      err = 'cannot open namelist file '''//path//''': no such file'
      return
    end if
    open (newunit=unit, file=path, access='stream', form='unformatted', action='read', &
          status='old', iostat=ios, iomsg=msg)
    if (ios /= 0) then
      err = 'cannot open namelist file '''//path//''': '//trim(msg)
      return
    end if
    inquire (unit=unit, size=nbytes)
    if (nbytes > 0) then
      deallocate (text)
      allocate (character(len=nbytes) :: text)
      read (unit, iostat=ios, iomsg=msg) text
    else
      ! no size: a pipe (/dev/stdin, <(...)) or an empty file; read to its end
      call read_to_end(ios)
    end if
    if (ios /= 0) err = 'cannot read namelist file '''//path//''': '//trim(msg)
    close (unit)
  contains
    !> text = every byte up to the end of the unit (append_text: linear time).
    subroutine read_to_end(ios)
      integer, intent(out) :: ios
      character(len=:), allocatable :: buffer
      character(len=1) :: c
      integer :: n
      n = 0
      call append_text(buffer, n, '')
      do
        read (unit, iostat=ios, iomsg=msg) c
        if (ios /= 0) exit
        call append_text(buffer, n, c)
      end do
      if (is_iostat_end(ios)) ios = 0
      text = buffer(1:n)
    end subroutine read_to_end
  end subroutine read_text_file

  !> Usage, options and a word on the input, to `unit`.
  subroutine print_help(unit)
    integer, intent(in) :: unit
    type(config_t), target :: defaults
    type(registry_t) :: reg
    character(len=:), allocatable :: groups
    integer :: j
    call build_registry(defaults, reg)
    groups = '&'//reg%keys(1)%group
    do j = 2, size(reg%keys)
      if (reg%keys(j)%group /= reg%keys(j - 1)%group) groups = groups//', &'//reg%keys(j)%group
    end do
    write (unit, '(a)') USAGE, &
      '       mpirun -n N dktlbm FILE ...', &
      '', &
      'Particles settling in a 2-D channel, D2Q9 lattice Boltzmann (MRT), on MPI ranks.', &
      '', &
      'options:', &
      '  FILE                   the scene: a namelist file, e.g. input/case1.nml', &
      '  --set group.key=value  set one key after FILE is read (also --set=group.key=value);', &
      '                         repeatable; array elements as key(2)=value; strings need no', &
      '                         quotes, e.g. --set lbm.tau=0.7 --set output.dir=/tmp/run', &
      '  --restart CHECKPOINT   resume the run from a checkpoint file it wrote (same FILE', &
      '                         and --set options; any number of ranks); the output continues', &
      '  --check                validate, print the derived lattice parameters and exit;', &
      '                         no lattice is allocated. Exits non-zero for whatever the', &
      '                         run would refuse (memory, an earlier run''s files in', &
      '                         output.dir). With --restart the checkpoint is not read', &
      '  --print-defaults       print every key with its default, unit, allowed values and', &
      '                         meaning, as a namelist file, and exit; with FILE (and', &
      '                         --set) the values they give instead of the defaults', &
      '  --help                 print this help and exit', &
      '  --version              print the version and exit', &
      '', &
      'The input file holds namelist groups in physical units (cm, g, s):', &
      '  '//groups, &
      'A group starts with &name, holds key = value items separated by commas or newlines,', &
      'and ends with /; ! starts a comment. A key not given keeps its default. An invalid', &
      'key or value stops the run with a message naming the file, line, group, key, value', &
      'and what is allowed. All keys: dktlbm --print-defaults, or input/README.md.'
  end subroutine print_help

  ! ---------------------------------------------------------------- helpers

  !> 'input/case1.nml' -> 'case1'; 'unnamed' for an empty name.
  function basename(path) result(name)
    character(len=*), intent(in) :: path
    character(len=:), allocatable :: name
    integer :: p
    name = path(index(path, '/', back=.true.) + 1:)
    p = index(name, '.', back=.true.)
    if (p > 1) name = name(:p - 1)
    if (len(name) == 0) name = 'unnamed'
  end function basename

end module dkt_config

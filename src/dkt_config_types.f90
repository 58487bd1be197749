!> The typed input of dktlbm: one type per namelist group in physical units (cm, g, s), each
!> with its defaults in its initialisers and a `register` procedure that binds its keys, with
!> unit, range and meaning, into the registry (dkt_registry).
!>
!> Defaults are written in one place only, the type initialisers below (a particle's in
!> particle_cfg_t). Parsing, range checks, `--print-defaults` and input/README.md (through
!> tests/test_input_readme.py) all come from the registry that config_registry builds.
module dkt_config_types
  use dkt_kinds, only: wp, MAX_PARTICLES
  use dkt_choices, only: choice_code, END_NAMES, COLLISION_NAMES, STREAMING_NAMES, &
                         PRECISION_NAMES, PROFILE_NAMES, FLOW_NAMES, MOTION_NAMES, BB_NAMES, &
                         MOMENTUM_NAMES, INTERIOR_NAMES, PRESSURE_NAMES
  use dkt_registry, only: registry_t, key_t, add_real, add_reals, add_integer, add_logical, &
                          add_string, add_choice, add_choices, rebind_grown
  use dkt_text, only: itoa
  implicit none
  private
  public :: config_registry, config_groups, particles_allocate, config_choices

  real(wp), parameter, public :: TAU_MAX = 10.0_wp !! the largest lbm.tau, typed or set by lbm.mach
  !> more time steps than this is surely a unit or typing error (a day at 10^4 steps/s)
  real(wp), parameter, public :: MAX_STEPS = 1.0e9_wp

  !> &domain: the channel.
  type, public :: domain_cfg_t
    real(wp) :: width = 2.0_wp            !! cm, channel width (x)
    real(wp) :: height = 5.0_wp           !! cm, channel length (y)
    character(len=16) :: sides = 'wall'   !! boundary at x = 0 and x = width
    character(len=16) :: lower = 'wall'   !! boundary at the y = 0 end
    character(len=16) :: upper = 'wall'   !! boundary at the y = height end
    integer :: sides_kind = 0             !! END_* of sides, set from the text (config_choices)
    integer :: lower_kind = 0             !! END_* of lower (config_choices)
    integer :: upper_kind = 0             !! END_* of upper (config_choices)
  contains
    procedure :: register => domain_register
  end type domain_cfg_t

  !> &fluid: the Newtonian fluid.
  type, public :: fluid_cfg_t
    real(wp) :: density = 1.0_wp          !! g/cm^3
    real(wp) :: viscosity = 0.01_wp       !! g/(cm s), dynamic viscosity mu
    real(wp) :: body_force(2) = 0.0_wp    !! cm/s^2, uniform acceleration on the fluid
  contains
    procedure :: register => fluid_register
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
    !> population storage: 'double' (8 bytes), 'single' (f_i - w_i in 4 bytes), 'single_arith'
    !! (stored as 'single', collided in 4 bytes), 'half' (f_i - w_i in 16-bit codes, collided in
    !! 4 bytes) or 'single_unshifted' (f_i in 4 bytes; only to measure what the shift buys)
    character(len=16) :: precision = 'double'
    integer :: collision_kind = 0         !! COLLISION_* of collision (config_choices)
    integer :: streaming_kind = 0         !! STREAMING_* of streaming (config_choices)
    integer :: precision_kind = 0         !! PRECISION_* of precision (config_choices)
  contains
    procedure :: register => lbm_register
  end type lbm_cfg_t

  !> &inlet: a 'velocity' end of the channel.
  type, public :: inlet_cfg_t
    real(wp) :: velocity = 0.0_wp             !! cm/s, signed y-velocity (centreline if parabolic)
    character(len=16) :: profile = 'parabolic' !! 'uniform' or 'parabolic'
    integer :: profile_kind = 0               !! PROFILE_* of profile (config_choices)
    real(wp) :: ramp_time = 0.0_wp            !! s, smooth ramp-up time of the inlet velocity
  contains
    procedure :: register => inlet_register
  end type inlet_cfg_t

  !> &initial: the flow at t = 0.
  type, public :: initial_cfg_t
    character(len=16) :: flow = 'rest'    !! 'rest' or 'taylor_green'
    integer :: flow_kind = 0              !! FLOW_* of flow (config_choices)
    real(wp) :: velocity = 0.0_wp         !! cm/s, amplitude of the initial flow
    character(len=16) :: pressure = 'uniform' !! 'uniform' or 'hydrostatic'
    integer :: pressure_kind = 0          !! PRESSURE_* of pressure (config_choices)
  contains
    procedure :: register => initial_register
  end type initial_cfg_t

  !> One particle of &particles with its defaults: element k of each array of particles_cfg_t
  !! starts as this (particles_allocate).
  type, public :: particle_cfg_t
    real(wp) :: diameter = 0.2_wp          !! cm
    real(wp) :: density = 1.01_wp          !! g/cm^3
    real(wp) :: x = 1.0_wp                 !! cm, centre across the channel
    real(wp) :: y = 1.0_wp                 !! cm, centre along the channel
    real(wp) :: u = 0.0_wp                 !! cm/s, initial (or prescribed) x-velocity
    real(wp) :: v = 0.0_wp                 !! cm/s, initial (or prescribed) y-velocity
    real(wp) :: omega = 0.0_wp             !! 1/s, initial (or prescribed) spin
    character(len=16) :: motion = 'free'   !! 'free', 'fixed' or 'prescribed'
  end type particle_cfg_t

  !> &particles: rigid circular particles (docs/model.md §3), in physical units. Element k of each
  !! array belongs to particle k; only particles 1..count are used. config_load grows the
  !! arrays while it reads (config_registry with grow) and then sizes them as the input asks
  !! (particle_slots), at least 1; particles_allocate sizes them for a configuration built in
  !! code, each new element as particle_cfg_t.
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
    integer, allocatable :: motion_kind(:)            !! MOTION_* of motion (config_choices)
    real(wp) :: gravity = 980.0_wp                    !! cm/s^2, along -y on the particles (E9)
  contains
    procedure :: register => particles_register
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
  contains
    procedure :: register => pair_register
  end type pair_cfg_t

  !> &window: the computational window that follows the particles down an infinite channel
  !! (docs/model.md §5). Lengths in D_1, the largest diameter.
  type, public :: window_cfg_t
    logical :: enabled = .false.            !! follow the particles; domain height/ends derived
    real(wp) :: below = 10.0_wp             !! D_1 from the lowest centre down to the lower end
    real(wp) :: above = 15.0_wp             !! D_1 from the lowest centre up to the upper end
    real(wp) :: margin = 1.0_wp             !! D_1: a particle this close to the upper end ends
                                            !! the run (the pair separated beyond the window)
    real(wp) :: max_above = -1.0_wp         !! D_1: the window grows up to this length above the
                                            !! lowest centre instead of ending the run; 0 = never;
                                            !! -1 = as the run needs (window_max_above)
  contains
    procedure :: register => window_register
  end type window_cfg_t

  !> &diagnostics: the thresholds of a kissing episode (docs/model.md §6), each the larger of a
  !! number of lattice spacings and a fraction of D_1.
  type, public :: diagnostics_cfg_t
    real(wp) :: enter_cells = 0.0_wp        !! an episode starts at D_r <= this many spacings
                                            !! (0 = collision.range + 1, just outside E10) ..
    real(wp) :: enter_d1 = 0.05_wp          !! .. or this fraction of D_1, whichever is larger
    real(wp) :: release_cells = 4.0_wp      !! it ends at D_r > this many spacings ..
    real(wp) :: release_d1 = 0.25_wp        !! .. or this fraction of D_1, whichever is larger
    logical :: pair = .false.               !! particles 1 and 2 are a pair in a larger scene
  contains
    procedure :: register => diagnostics_register
  end type diagnostics_cfg_t

  !> &coupling: how the particles and the fluid exchange momentum.
  type, public :: coupling_cfg_t
    character(len=16) :: bounce_back = 'yu' !! 'halfway', 'yu' or 'bfl' (E6)
    character(len=16) :: momentum = 'paper' !! 'paper' or 'galilean' (E7)
    character(len=16) :: interior = 'solid' !! 'solid' or 'fluid' (nodes inside a particle)
    integer :: bounce_back_kind = 0         !! BB_* of bounce_back (config_choices)
    integer :: momentum_kind = 0            !! MOMENTUM_* of momentum (config_choices)
    integer :: interior_kind = 0            !! INTERIOR_* of interior (config_choices)
    logical :: average_force = .true.       !! move by the mean force of this step and the last (E8)
  contains
    procedure :: register => coupling_register
  end type coupling_cfg_t

  !> &collision: the short-range repulsion of Wan & Turek between particles and walls.
  type, public :: collision_cfg_t
    real(wp) :: stiffness = 1.0e-7_wp         !! cm^3 s^2/g, eps_p of E10 (per unit depth)
    real(wp) :: stiffness_overlap = 1.0e-7_wp !! cm^2 s^2/g, eps'_p of E10 (per unit depth)
    real(wp) :: range = 1.0_wp                !! threshold xi of E10, in lattice spacings
    integer :: substeps = 1                   !! particle sub-steps per fluid step
    logical :: lubrication = .false.          !! the lubrication correction E13
    real(wp) :: lubrication_range = 1.0_wp    !! its cut-off h_c, in lattice spacings
    real(wp) :: lubrication_min = 0.01_wp     !! the smallest gap h_min it is taken at, spacings
  contains
    procedure :: register => collision_register
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
    !> time steps between checks of the slabs' balance (a scene with particles on more than one
    !! rank); 0 = the rows stay split evenly
    integer :: balance_every = 500
    !> the costliest slab's modelled work over the mean above which the borders move
    real(wp) :: balance_threshold = 1.1_wp
    !> the keys a --restart may change on purpose, 'group.key' separated by commas or blanks
    !! (dkt_config_restart); '' = none beyond the run length, output and checkpoint keys
    character(len=1024) :: restart_changes = ''
  contains
    procedure :: register => run_register
  end type run_cfg_t

  !> &output: where and how often results are written.
  type, public :: output_cfg_t
    character(len=256) :: dir = ''        !! output directory; '' = runs/<namelist basename>
    real(wp) :: field_interval = 0.0_wp   !! s between field outputs; 0 = at the end only
    real(wp) :: series_interval = 0.0_wp  !! s between particle samples; 0 = every step
    logical :: overwrite = .false.        !! allow replacing an existing <dir>/<name>.h5
    integer :: compress = 0               !! deflate level of field snapshots, 0 = none
  contains
    procedure :: register => output_register
  end type output_cfg_t

  !> The whole input of a run.
  type, public :: config_t
    character(len=:), allocatable :: file !! namelist path as given
    character(len=:), allocatable :: name !! namelist basename without extension, e.g. 'case1'
    !> the input as read (namelist text), before &pair, &window and cells_per_diameter were
    !! turned into particles, domain and dx: reading it back gives the same configuration
    character(len=:), allocatable :: given
    !> the output directory: output.dir, or runs/<name> when that is empty (set at load)
    character(len=:), allocatable :: output_dir
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

contains

  !> Bind every input key to its component of `c`, with unit, range and meaning: each group
  !! registers its own keys, in the order they are documented and printed. With `grow`, the
  !! particle arrays grow while the registry reads, up to MAX_PARTICLES (particles_resize), so
  !! that config_load reads the input once and sizes them after; otherwise their sizes are
  !! fixed, and an element beyond them is an error.
  subroutine config_registry(c, reg, grow)
    type(config_t), intent(inout), target :: c
    type(registry_t), intent(out) :: reg
    logical, intent(in), optional :: grow
    if (present(grow)) then
      if (grow) then
        reg%resize => particles_resize
        reg%owner => c
        reg%limit = MAX_PARTICLES
      end if
    end if
    if (.not. allocated(c%particles%diameter)) &
      call particles_allocate(c%particles, max(1, c%particles%count))
    call c%domain%register(reg)
    call c%fluid%register(reg)
    call c%lbm%register(reg)
    call c%inlet%register(reg)
    call c%initial%register(reg)
    call c%particles%register(reg)
    call c%pair%register(reg)
    call c%window%register(reg)
    call c%diagnostics%register(reg)
    call c%coupling%register(reg)
    call c%collision%register(reg)
    call c%run%register(reg)
    call c%output%register(reg)
  end subroutine config_registry

  !> The namelist groups in order, as text: '&domain, &fluid, ..' (from the registry).
  function config_groups() result(s)
    character(len=:), allocatable :: s
    type(config_t), target :: defaults
    type(registry_t) :: reg
    integer :: a, b
    call config_registry(defaults, reg)
    s = ''
    a = 1
    do while (a <= len(reg%groups))
      b = index(reg%groups(a:)//' ', ' ') + a - 1
      if (len(s) > 0) s = s//', '
      s = s//'&'//reg%groups(a:b - 1)
      a = b + 1
    end do
  end function config_groups

  !> Each choice of `c` as its named constant (dkt_choices), from its text: done once at load,
  !! after the scene keys are expanded, so that the rest of the program compares integers. The
  !! texts stay for messages, the namelist text and the run file. A text that is not a choice
  !! gives 0, which every `select case` on the constant refuses as an internal error.
  subroutine config_choices(c)
    type(config_t), intent(inout) :: c
    integer :: k
    c%domain%sides_kind = choice_code(c%domain%sides, END_NAMES)
    c%domain%lower_kind = choice_code(c%domain%lower, END_NAMES)
    c%domain%upper_kind = choice_code(c%domain%upper, END_NAMES)
    c%lbm%collision_kind = choice_code(c%lbm%collision, COLLISION_NAMES)
    c%lbm%streaming_kind = choice_code(c%lbm%streaming, STREAMING_NAMES)
    c%lbm%precision_kind = choice_code(c%lbm%precision, PRECISION_NAMES)
    c%inlet%profile_kind = choice_code(c%inlet%profile, PROFILE_NAMES)
    c%initial%flow_kind = choice_code(c%initial%flow, FLOW_NAMES)
    c%initial%pressure_kind = choice_code(c%initial%pressure, PRESSURE_NAMES)
    if (allocated(c%particles%motion)) &
      c%particles%motion_kind = [(choice_code(c%particles%motion(k), MOTION_NAMES), &
                                  k=1, size(c%particles%motion))]
    c%coupling%bounce_back_kind = choice_code(c%coupling%bounce_back, BB_NAMES)
    c%coupling%momentum_kind = choice_code(c%coupling%momentum, MOMENTUM_NAMES)
    c%coupling%interior_kind = choice_code(c%coupling%interior, INTERIOR_NAMES)
  end subroutine config_choices

  !> Size the particle arrays of `p` to `n` elements: elements 1..min(n, old size) keep their
  !! values, the others take the defaults of particle_cfg_t.
  subroutine particles_allocate(p, n)
    type(particles_cfg_t), intent(inout) :: p
    integer, intent(in) :: n
    type(particle_cfg_t) :: d
    call resize(p%diameter, d%diameter)
    call resize(p%density, d%density)
    call resize(p%x, d%x)
    call resize(p%y, d%y)
    call resize(p%u, d%u)
    call resize(p%v, d%v)
    call resize(p%omega, d%omega)
    block
      character(len=16), allocatable :: t(:)
      allocate (t(n))
      t = d%motion
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

  !> The resize hook of a registry that grows (config_registry): the particle arrays of the
  !! configuration `owner` get n elements (particles_allocate: values kept, new elements at
  !! the defaults), and the keys that grow are bound to them anew as particles_register binds
  !! them, so that the keys are declared in one place.
  subroutine particles_resize(owner, keys, n)
    class(*), pointer, intent(in) :: owner
    type(key_t), intent(inout) :: keys(:)
    integer, intent(in) :: n
    type(registry_t) :: fresh
    select type (c => owner)
    type is (config_t)
      call particles_allocate(c%particles, n)
      call c%particles%register(fresh)
      call rebind_grown(keys, fresh)
    class default
      error stop 'dktlbm: error: internal error: particles_resize: the owner is no config_t'
    end select
  end subroutine particles_resize

  !> Register the keys of &domain, each bound to its component of `self`.
  subroutine domain_register(self, reg)
    class(domain_cfg_t), intent(inout), target :: self
    type(registry_t), intent(inout) :: reg
    call add_real(reg, 'domain', 'width', self%width, 'cm', &
                  'channel width (x, across the channel)', gt=0.0_wp)
    call add_real(reg, 'domain', 'height', self%height, 'cm', &
                  'channel length (y, along the channel axis)', gt=0.0_wp)
    call add_choice(reg, 'domain', 'sides', self%sides, 'wall periodic', &
                    'boundary at x = 0 and x = width')
    call add_choice(reg, 'domain', 'lower', self%lower, END_NAMES, &
                    'boundary at the lower end y = 0 (velocity, outflow: E5)')
    call add_choice(reg, 'domain', 'upper', self%upper, END_NAMES, &
                    'boundary at the upper end y = height; periodic only with lower periodic')
  end subroutine domain_register

  !> Register the keys of &fluid, each bound to its component of `self`.
  subroutine fluid_register(self, reg)
    class(fluid_cfg_t), intent(inout), target :: self
    type(registry_t), intent(inout) :: reg
    call add_real(reg, 'fluid', 'density', self%density, 'g/cm^3', 'fluid density', gt=0.0_wp)
    call add_real(reg, 'fluid', 'viscosity', self%viscosity, 'g/(cm s)', &
                  'dynamic viscosity mu; the kinematic viscosity is mu/density', gt=0.0_wp)
    call add_reals(reg, 'fluid', 'body_force', self%body_force, 'cm/s^2', &
                   'uniform acceleration (x, y) on the fluid, for verification flows')
  end subroutine fluid_register

  !> Register the keys of &lbm, each bound to its component of `self`.
  subroutine lbm_register(self, reg)
    class(lbm_cfg_t), intent(inout), target :: self
    type(registry_t), intent(inout) :: reg
    call add_real(reg, 'lbm', 'dx', self%dx, 'cm', 'lattice spacing', gt=0.0_wp)
    call add_real(reg, 'lbm', 'tau', self%tau, '-', &
                  'relaxation time in time steps; sets nu_lb = (tau - 1/2)/3 and dt (E3); '// &
                  'not used when lbm.mach > 0', gt=0.5_wp, le=TAU_MAX)
    call add_choice(reg, 'lbm', 'collision', self%collision, COLLISION_NAMES, &
                    'collision model: multiple-relaxation-time (E1) or BGK (E4)')
    call add_real(reg, 'lbm', 's_e', self%s_e, '-', 'MRT rate of the energy moment (E3)', &
                  gt=0.0_wp, lt=2.0_wp)
    call add_real(reg, 'lbm', 's_eps', self%s_eps, '-', &
                  'MRT rate of the energy-square moment (E3)', gt=0.0_wp, lt=2.0_wp)
    call add_real(reg, 'lbm', 's_q', self%s_q, '-', 'MRT rate of the heat-flux moments; '// &
                  '0 = 8(2 - 1/tau)/(8 - 1/tau), which puts bounce-back walls half-way (E3)', &
                  gt=0.0_wp, lt=2.0_wp, zero_ok=.true.)
    call add_real(reg, 'lbm', 'cells_per_diameter', self%cells_per_diameter, '-', &
                  'lattice spacings across the smallest particle; > 0 sets dx = width/'// &
                  'nint(width n/D_min) in place of dx; 0 = use dx', ge=4.0_wp, le=1000.0_wp, &
                  zero_ok=.true.)
    call add_real(reg, 'lbm', 'mach', self%mach, '-', &
                  'target expected Mach number u_scale/c_s; > 0 sets tau = 1/2 + 3 mach c_s '// &
                  'nu/(u_scale dx) in place of tau (acoustic scaling: dt ~ dx), u_scale the '// &
                  'velocity scale of the report; 0 = use tau', gt=0.0_wp, le=1.0_wp, &
                  zero_ok=.true.)
    call add_choice(reg, 'lbm', 'precision', self%precision, PRECISION_NAMES, &
                    'population storage and arithmetic: 8 bytes; single: 4 bytes holding '// &
                    'f_i - w_i, collided in 8; single_arith: stored as single and collided in '// &
                    '4 bytes as f_i - w_i; half: f_i - w_i in 2 bytes (1 sign, 4 exponent, '// &
                    '11 mantissa bits), collided in 4; single_unshifted stores f_i in 4 bytes, '// &
                    'only to '// &
                    'measure what the shift buys, not for use')
    call add_choice(reg, 'lbm', 'streaming', self%streaming, STREAMING_NAMES, &
                    'one lattice swept in place, or two (read one, write the other); '// &
                    'the same results to the bit, in_place needs half the memory')
  end subroutine lbm_register

  !> Register the keys of &inlet, each bound to its component of `self`.
  subroutine inlet_register(self, reg)
    class(inlet_cfg_t), intent(inout), target :: self
    type(registry_t), intent(inout) :: reg
    call add_real(reg, 'inlet', 'velocity', self%velocity, 'cm/s', &
                  'signed y-velocity at a velocity end (centreline value if parabolic)')
    call add_choice(reg, 'inlet', 'profile', self%profile, PROFILE_NAMES, &
                    'shape of the inlet velocity across the channel')
    call add_real(reg, 'inlet', 'ramp_time', self%ramp_time, 's', &
                  'the inlet velocity ramps up smoothly over this time; 0 = at once', ge=0.0_wp)
  end subroutine inlet_register

  !> Register the keys of &initial, each bound to its component of `self`.
  subroutine initial_register(self, reg)
    class(initial_cfg_t), intent(inout), target :: self
    type(registry_t), intent(inout) :: reg
    call add_choice(reg, 'initial', 'flow', self%flow, FLOW_NAMES, &
                    'flow at t = 0; taylor_green needs periodic sides and ends')
    call add_real(reg, 'initial', 'velocity', self%velocity, 'cm/s', &
                  'amplitude of the initial flow', ge=0.0_wp)
    call add_choice(reg, 'initial', 'pressure', self%pressure, PRESSURE_NAMES, &
                    'pressure at t = 0: uniform, or hydrostatic: at each height the weight '// &
                    'less buoyancy of the free particles above it per unit width, so that a '// &
                    'closed box does not ring when they start to fall')
  end subroutine initial_register

  !> Register the keys of &particles, each bound to its component of `self`.
  subroutine particles_register(self, reg)
    class(particles_cfg_t), intent(inout), target :: self
    type(registry_t), intent(inout) :: reg
    integer :: j
    call add_integer(reg, 'particles', 'count', self%count, '-', &
                     'number of particles; sets the size of each array, particle k uses '// &
                     'element k; at most what a checkpoint holds', &
                     ge=0, le=MAX_PARTICLES)
    call add_reals(reg, 'particles', 'diameter', self%diameter, 'cm', &
                   'particle diameter', gt=0.0_wp)
    call add_reals(reg, 'particles', 'density', self%density, 'g/cm^3', &
                   'particle density', gt=0.0_wp)
    call add_reals(reg, 'particles', 'x', self%x, 'cm', &
                   'x of the centre at t = 0 (across the channel)')
    call add_reals(reg, 'particles', 'y', self%y, 'cm', &
                   'y of the centre at t = 0 (along the channel)')
    call add_reals(reg, 'particles', 'u', self%u, 'cm/s', &
                   'x-velocity at t = 0, kept if prescribed, 0 if fixed')
    call add_reals(reg, 'particles', 'v', self%v, 'cm/s', &
                   'y-velocity at t = 0, kept if prescribed, 0 if fixed')
    call add_reals(reg, 'particles', 'omega', self%omega, '1/s', &
                   'counter-clockwise angular velocity at t = 0, kept if prescribed, 0 if fixed')
    call add_choices(reg, 'particles', 'motion', self%motion, MOTION_NAMES, &
                     'free (moved by fluid and gravity, E8), fixed (at rest) or prescribed '// &
                     '(u, v, omega kept)')
    do j = 1, size(reg%keys)
      if (reg%keys(j)%group /= 'particles' .or. reg%keys(j)%n == 0) cycle
      reg%keys(j)%grows = .true.
      reg%keys(j)%size_note = ' (the particle arrays have particles.count elements, at '// &
                              'least 1; raise particles.count for more particles, at most '// &
                              itoa(MAX_PARTICLES)//')'
    end do
    call add_real(reg, 'particles', 'gravity', self%gravity, 'cm/s^2', &
                  'gravity on the particles, along -y; acts as weight minus buoyancy (E9)', &
                  ge=0.0_wp)
  end subroutine particles_register

  !> Register the keys of &pair, each bound to its component of `self`.
  subroutine pair_register(self, reg)
    class(pair_cfg_t), intent(inout), target :: self
    type(registry_t), intent(inout) :: reg
    call add_real(reg, 'pair', 'gamma', self%gamma, '-', 'diameter ratio D_1/D_2 of a '// &
                  'DKT pair; > 0 sets particles 1 (D_1) and 2 (D_1/gamma); 0 = no pair', &
                  ge=1.0_wp, le=100.0_wp, zero_ok=.true.)
    call add_real(reg, 'pair', 'd1', self%d1, 'cm', 'diameter D_1 of the larger particle', &
                  gt=0.0_wp)
    call add_real(reg, 'pair', 'dh', self%dh, '-', &
                  'initial distance D_h of the centres along y, in D_1', gt=0.0_wp)
    call add_choice(reg, 'pair', 'upper', self%upper, 'larger smaller', &
                    'which particle starts above the other (case1: larger, case2: smaller)')
    call add_real(reg, 'pair', 'y_upper', self%y_upper, 'cm', &
                  'y of the upper particle''s centre at t = 0')
    call add_real(reg, 'pair', 'x_offset', self%x_offset, 'cm', 'the upper particle '// &
                  'starts this far right of the centreline, breaking the mirror symmetry')
    call add_real(reg, 'pair', 'density', self%density, 'g/cm^3', &
                  'density of both particles', gt=0.0_wp)
  end subroutine pair_register

  !> Register the keys of &window, each bound to its component of `self`.
  subroutine window_register(self, reg)
    class(window_cfg_t), intent(inout), target :: self
    type(registry_t), intent(inout) :: reg
    call add_logical(reg, 'window', 'enabled', self%enabled, 'follow the lowest '// &
                     'particle down an infinite channel; sets the domain height and ends '// &
                     '(docs/model.md section 5)')
    call add_real(reg, 'window', 'below', self%below, '-', &
                  'window length below the lowest particle''s centre, in D_1', ge=1.0_wp)
    call add_real(reg, 'window', 'above', self%above, '-', &
                  'window length above the lowest particle''s centre, in D_1', ge=1.0_wp)
    call add_real(reg, 'window', 'margin', self%margin, '-', 'a particle that comes '// &
                  'this close (in D_1) to the upper end grows the window (max_above) or, '// &
                  'when it cannot grow, ends the run early', ge=0.0_wp)
    call add_real(reg, 'window', 'max_above', self%max_above, '-', 'the longest the '// &
                  'window may grow above the lowest particle''s centre, in D_1 (>= above): '// &
                  'it grows by above/2 at a time when a particle comes within margin of its '// &
                  'upper end; 0: it never grows; -1: as far as the run needs, above plus the '// &
                  'settling-speed scale times the run''s length, at most 20 above '// &
                  '(docs/model.md section 5)', ge=1.0_wp, zero_ok=.true., auto_ok=.true.)
  end subroutine window_register

  !> Register the keys of &diagnostics, each bound to its component of `self`.
  subroutine diagnostics_register(self, reg)
    class(diagnostics_cfg_t), intent(inout), target :: self
    type(registry_t), intent(inout) :: reg
    call add_real(reg, 'diagnostics', 'enter_cells', self%enter_cells, '-', &
                  'a kissing episode starts at D_r <= max(enter_cells dx, enter_d1 D_1); '// &
                  '0 = collision.range + 1', gt=0.0_wp, zero_ok=.true.)
    call add_real(reg, 'diagnostics', 'enter_d1', self%enter_d1, '-', &
                  'see enter_cells', ge=0.0_wp)
    call add_real(reg, 'diagnostics', 'release_cells', self%release_cells, '-', &
                  'an episode ends at D_r > max(release_cells dx, release_d1 D_1)', ge=0.0_wp)
    call add_real(reg, 'diagnostics', 'release_d1', self%release_d1, '-', &
                  'see release_cells', ge=0.0_wp)
    call add_logical(reg, 'diagnostics', 'pair', self%pair, 'the pair diagnostics of '// &
                     'particles 1 and 2 in a scene of more than two; a pair scene (&pair) '// &
                     'or a scene of two particles has them always')
  end subroutine diagnostics_register

  !> Register the keys of &coupling, each bound to its component of `self`.
  subroutine coupling_register(self, reg)
    class(coupling_cfg_t), intent(inout), target :: self
    type(registry_t), intent(inout) :: reg
    call add_choice(reg, 'coupling', 'bounce_back', self%bounce_back, BB_NAMES, &
                    'bounce-back on the particle surface: half-way, Yu et al. or BFL (E6)')
    call add_choice(reg, 'coupling', 'momentum', self%momentum, MOMENTUM_NAMES, &
                    'momentum exchange: the paper''s rule or Galilean-invariant (E7)')
    call add_choice(reg, 'coupling', 'interior', self%interior, INTERIOR_NAMES, &
                    'nodes inside a particle: reset to the rigid-body equilibrium, or fluid '// &
                    'bounced from both sides of the surface')
    call add_logical(reg, 'coupling', 'average_force', self%average_force, 'move a free '// &
                     'particle by the mean hydrodynamic force and torque of this step and '// &
                     'the last (Ladd), which keeps a light disk near a wall or another disk '// &
                     'stable; .false. = the force of the step alone (the paper''s E8)')
  end subroutine coupling_register

  !> Register the keys of &collision, each bound to its component of `self`.
  subroutine collision_register(self, reg)
    class(collision_cfg_t), intent(inout), target :: self
    type(registry_t), intent(inout) :: reg
    call add_real(reg, 'collision', 'stiffness', self%stiffness, 'cm^3 s^2/g', &
                  'eps_p of E10 for a gap below range (wall: eps_p/2, E11)', gt=0.0_wp)
    call add_real(reg, 'collision', 'stiffness_overlap', self%stiffness_overlap, &
                  'cm^2 s^2/g', 'eps''_p of E10 for overlapping particles (wall: half, E11)', &
                  gt=0.0_wp)
    call add_real(reg, 'collision', 'range', self%range, '-', &
                  'threshold xi of E10 in lattice spacings: repulsion acts below this gap', &
                  ge=0.0_wp)
    call add_integer(reg, 'collision', 'substeps', self%substeps, '-', &
                     'particle sub-steps per fluid time step (for a stiff repulsion)', &
                     ge=1, le=1000)
    call add_logical(reg, 'collision', 'lubrication', self%lubrication, 'the lubrication '// &
                     'correction (E13): the normal force of the film between two disks or a '// &
                     'disk and a wall below the gap the lattice resolves')
    call add_real(reg, 'collision', 'lubrication_range', self%lubrication_range, '-', &
                  'cut-off h_c of E13 in lattice spacings: the gap from which the lattice '// &
                  'resolves the film', gt=0.0_wp, le=10.0_wp)
    call add_real(reg, 'collision', 'lubrication_min', self%lubrication_min, '-', &
                  'the smallest gap h_min of E13 in lattice spacings (a roughness): a '// &
                  'smaller gap takes the force of this one', gt=0.0_wp, le=10.0_wp)
  end subroutine collision_register

  !> Register the keys of &run, each bound to its component of `self`.
  subroutine run_register(self, reg)
    class(run_cfg_t), intent(inout), target :: self
    type(registry_t), intent(inout) :: reg
    call add_real(reg, 'run', 't_end', self%t_end, 's', &
                  'simulated time (ignored when steps > 0)', gt=0.0_wp)
    call add_integer(reg, 'run', 'steps', self%steps, '-', &
                     'number of time steps; 0 = from t_end', ge=0, le=nint(MAX_STEPS))
    call add_real(reg, 'run', 't_ref', self%t_ref, 's', &
                  'time scale of t* = t/t_ref; default sqrt(18 cm / 980 cm/s^2)', gt=0.0_wp)
    call add_integer(reg, 'run', 'progress_every', self%progress_every, '-', &
                     'time steps between progress lines; 0 = none', ge=0)
    call add_integer(reg, 'run', 'guard_every', self%guard_every, '-', &
                     'time steps between the NaN and Mach-number guards', ge=1)
    call add_real(reg, 'run', 'mach_limit', self%mach_limit, '-', &
                  'largest allowed Mach number u/c_s before the run is stopped', &
                  gt=0.0_wp, le=1.0_wp)
    call add_real(reg, 'run', 'particle_speed_limit', self%particle_speed_limit, '-', &
                  'largest allowed particle speed in lattice spacings per time step, '// &
                  'checked every step; a faster particle stops the run', gt=0.0_wp, le=1.0_wp)
    call add_integer(reg, 'run', 'checkpoint_every', self%checkpoint_every, '-', &
                     'time steps between checkpoints; 0 = none by step count', ge=0)
    call add_real(reg, 'run', 'checkpoint_wall', self%checkpoint_wall, 's', &
                  'wall-clock time between checkpoints; 0 = none by wall time', ge=0.0_wp)
    call add_integer(reg, 'run', 'checkpoint_keep', self%checkpoint_keep, '-', &
                     'newest checkpoints kept; older ones are deleted', ge=1)
    call add_real(reg, 'run', 'wall_limit', self%wall_limit, 's', 'after this wall-clock '// &
                  'time the run writes a checkpoint and stops (exit 0); 0 = no limit', ge=0.0_wp)
    call add_real(reg, 'run', 'memory_limit', self%memory_limit, 'GiB', 'memory the ranks '// &
                  'of one node may use together; a run needing more is refused at start; '// &
                  '0 = MemAvailable of /proc/meminfo', ge=0.0_wp)
    call add_integer(reg, 'run', 'balance_every', self%balance_every, '-', 'time steps '// &
                     'between checks of the slabs'' balance with particles on more than one '// &
                     'rank: the slab borders move so that each rank''s modelled work is equal; '// &
                     '0 = the rows stay split evenly', ge=0)
    call add_real(reg, 'run', 'balance_threshold', self%balance_threshold, '-', 'the '// &
                  'costliest slab''s modelled work over the mean slab''s above which a check '// &
                  'moves the borders', ge=1.0_wp, le=100.0_wp)
    call add_string(reg, 'run', 'restart_changes', self%restart_changes, 'keys a --restart '// &
                    'may change on purpose, as group.key separated by commas (e.g. '// &
                    '''pair.density, particles.gravity''); the changes are recorded in the run '// &
                    'file; empty = only the run length, output and checkpoint keys')
  end subroutine run_register

  !> Register the keys of &output, each bound to its component of `self`.
  subroutine output_register(self, reg)
    class(output_cfg_t), intent(inout), target :: self
    type(registry_t), intent(inout) :: reg
    call add_string(reg, 'output', 'dir', self%dir, &
                    'output directory; empty = runs/<namelist basename>')
    call add_real(reg, 'output', 'field_interval', self%field_interval, 's', &
                  'time between field outputs; 0 = fields at the end only', ge=0.0_wp)
    call add_real(reg, 'output', 'series_interval', self%series_interval, 's', &
                  'time between samples of the /particles series; 0 = every step', ge=0.0_wp)
    call add_logical(reg, 'output', 'overwrite', self%overwrite, &
                     'allow replacing an existing <dir>/<name>.h5')
    call add_integer(reg, 'output', 'compress', self%compress, '-', 'deflate (gzip) '// &
                     'level of the field snapshots, 1 fastest .. 9 smallest; 0 = uncompressed', &
                     ge=0, le=9)
  end subroutine output_register

end module dkt_config_types

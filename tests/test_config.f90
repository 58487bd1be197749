!> Unit tests of module dkt_config: namelist text and --set overrides in, configuration or a
!> clear error out. No files and no MPI: every namelist is a string given to config_load.
!>
!> Expected values come from the input contract (notes of the configuration type, docs/model.md
!> E3/E4) and from the texts the tests write, never from the program's own output.
program test_config
  use, intrinsic :: iso_fortran_env, only: int64
  use dkt_kinds, only: wp
  use dkt_config, only: config_t, lattice_params_t, cli_t, config_load, config_validate, &
                        config_check_text, &
                        derive_lattice, config_to_namelist, parse_arguments, read_text_file, &
                        config_output_dir, particles_allocate, particles_cfg_t, MAX_PARTICLES, &
                        particle_cfg_t
  use dkt_text, only: printable
  use dkt_registry, only: registry_t, KEY_CHOICE, find_key, final_size
  use dkt_namelist, only: parse_namelist, apply_override
  use dkt_config, only: config_registry, config_choices
  use dkt_choices, only: END_WALL, END_PERIODIC, END_VELOCITY, END_OUTFLOW, COLLISION_MRT, &
                         COLLISION_BGK, STREAMING_IN_PLACE, STREAMING_TWO_LATTICE, &
                         PRECISION_DOUBLE, PRECISION_SINGLE, PROFILE_UNIFORM, &
                         PROFILE_PARABOLIC, FLOW_REST, FLOW_TAYLOR_GREEN, MOTION_FREE, &
                         MOTION_PRESCRIBED, BB_YU, BB_BFL, MOMENTUM_PAPER, MOMENTUM_GALILEAN, &
                         INTERIOR_SOLID, INTERIOR_FLUID
  implicit none

  character(len=*), parameter :: NL = new_line('a')
  character(len=*), parameter :: FILE = 'input/test.nml'
  character(len=1) :: none(0) !! no overrides
  !> Sizes the particle arrays to 16 elements (count 0: the highest element given, here u(16)
  !! set to its default), so that checks of the namelist forms can look at the elements after
  !! those a text sets.
  character(len=*), parameter :: P16 = '&particles u(16) = 0 /'//NL
  integer :: n_pass = 0, n_fail = 0

  call test_defaults()
  call test_value_forms()
  call test_arrays_strings_logicals()
  call test_syntax_forms()
  call test_overrides()
  call test_round_trip()
  call test_cross_checks_accept()
  call test_derive_lattice()
  call test_load_returns_lattice()
  call test_command_line()
  call test_errors()
  call test_particle_keys()
  call test_particle_sizing()
  call test_particle_growth()
  call test_particle_scenes_accept()
  call test_particle_warnings()
  call test_particle_errors()
  call test_nml_repeat_counts()
  call test_nml_null_values()
  call test_nml_sections()
  call test_nml_group_forms()
  call test_nml_strings()
  call test_nml_logicals()
  call test_nml_reals()
  call test_nml_overrides()
  call test_nml_errors()
  call test_derived_and_text_errors()
  call test_input_defects()
  call test_choice_codes()

  write (*, '(i0,a,i0,a)') n_pass, ' passed, ', n_fail, ' failed'
  if (n_fail > 0) error stop 1

contains

  subroutine check(name, ok)
    character(len=*), intent(in) :: name
    logical, intent(in) :: ok
    if (ok) then
      n_pass = n_pass + 1
      write (*, '(a)') 'PASS '//name
    else
      n_fail = n_fail + 1
      write (*, '(a)') 'FAIL '//name
    end if
  end subroutine check

  !> Exact equality, bit for bit: a value read from text must be the very same real.
  elemental logical function same(a, b)
    real(wp), intent(in) :: a, b
    same = transfer(a, 0_int64) == transfer(b, 0_int64)
  end function same

  logical function close_to(a, b)
    real(wp), intent(in) :: a, b
    close_to = abs(a - b) <= 1.0e-12_wp*max(abs(a), abs(b), tiny(1.0_wp))
  end function close_to

  !> Load `text` (plus overrides); report a failed check with the error if it is not accepted.
  subroutine load_ok(name, text, cfg, overrides)
    character(len=*), intent(in) :: name, text
    type(config_t), intent(out) :: cfg
    character(len=*), intent(in), optional :: overrides(:)
    character(len=:), allocatable :: err
    if (present(overrides)) then
      call config_load(cfg, text, FILE, overrides, err)
    else
      call config_load(cfg, text, FILE, none, err)
    end if
    if (len(err) > 0) write (*, '(a)') '  unexpected error: '//err
    call check(name//' is accepted', len(err) == 0)
  end subroutine load_ok

  !> `text` (plus overrides) must be refused with a message holding every one of `parts`.
  subroutine expect_error(name, text, parts, overrides)
    character(len=*), intent(in) :: name, text
    character(len=*), intent(in) :: parts(:)
    character(len=*), intent(in), optional :: overrides(:)
    type(config_t) :: cfg
    character(len=:), allocatable :: err
    if (present(overrides)) then
      call config_load(cfg, text, FILE, overrides, err)
    else
      call config_load(cfg, text, FILE, none, err)
    end if
    call expect_parts(name, err, parts)
  end subroutine expect_error

  subroutine expect_parts(name, err, parts)
    character(len=*), intent(in) :: name, err
    character(len=*), intent(in) :: parts(:)
    logical :: ok
    integer :: j
    ok = len(err) > 0
    do j = 1, size(parts)
      if (index(err, trim(parts(j))) == 0) then
        ok = .false.
        write (*, '(a)') '  missing '''//trim(parts(j))//''' in: '//err
      end if
    end do
    if (len(err) == 0) write (*, '(a)') '  no error was reported'
    call check(name, ok)
  end subroutine expect_parts

  subroutine test_defaults()
    type(config_t) :: cfg
    call load_ok('empty namelist', '', cfg)
    ! The documented defaults of the configuration contract.
    call check('default domain 2 x 5 cm, walls', same(cfg%domain%width, 2.0_wp) .and. &
               same(cfg%domain%height, 5.0_wp) .and. cfg%domain%sides == 'wall' .and. &
               cfg%domain%lower == 'wall' .and. cfg%domain%upper == 'wall')
    call check('default fluid rho 1, mu 0.01, no body force', &
               same(cfg%fluid%density, 1.0_wp) .and. same(cfg%fluid%viscosity, 0.01_wp) .and. &
               all(same(cfg%fluid%body_force, 0.0_wp)))
    call check('default lbm dx 0.004, tau 0.65, mrt with paper rates', &
               same(cfg%lbm%dx, 0.004_wp) .and. same(cfg%lbm%tau, 0.65_wp) .and. &
               cfg%lbm%collision == 'mrt' .and. same(cfg%lbm%s_e, 1.1_wp) .and. &
               same(cfg%lbm%s_eps, 1.25_wp) .and. same(cfg%lbm%s_q, 0.0_wp))
    call check('default run t_end 1 s, steps 0, guards every 100', &
               same(cfg%run%t_end, 1.0_wp) .and. cfg%run%steps == 0 .and. &
               cfg%run%guard_every == 100 .and. &
               cfg%run%progress_every == 1000 .and. same(cfg%run%mach_limit, 0.3_wp))
    call check('default output dir empty, no overwrite', cfg%output%dir == '' .and. &
               .not. cfg%output%overwrite .and. same(cfg%output%field_interval, 0.0_wp))
    call check('file and name kept: input/test.nml -> test', cfg%file == FILE .and. &
               cfg%name == 'test')
    call check('output dir defaults to runs/<name>', config_output_dir(cfg) == 'runs/test')
    call check('no particles given: every particle array holds one element', &
               size(cfg%particles%diameter) == 1 .and. size(cfg%particles%motion) == 1 .and. &
               size(cfg%particles%omega) == 1)
    call check('default particles: none; D 0.2 cm, rho_p 1.01, at (1, 1), at rest, free', &
               cfg%particles%count == 0 .and. all(same(cfg%particles%diameter, 0.2_wp)) .and. &
               all(same(cfg%particles%density, 1.01_wp)) .and. &
               all(same(cfg%particles%x, 1.0_wp)) .and. all(same(cfg%particles%y, 1.0_wp)) .and. &
               all(same(cfg%particles%u, 0.0_wp)) .and. all(same(cfg%particles%v, 0.0_wp)) .and. &
               all(same(cfg%particles%omega, 0.0_wp)) .and. all(cfg%particles%motion == 'free'))
    call check('default particle gravity 980 cm/s^2', same(cfg%particles%gravity, 980.0_wp))
    call check('default coupling: Yu bounce-back, the paper''s momentum exchange', &
               cfg%coupling%bounce_back == 'yu' .and. cfg%coupling%momentum == 'paper')
    call check('default collision: eps_p = eps''_p = 1e-7, range 1, one sub-step', &
               same(cfg%collision%stiffness, 1.0e-7_wp) .and. &
               same(cfg%collision%stiffness_overlap, 1.0e-7_wp) .and. &
               same(cfg%collision%range, 1.0_wp) .and. cfg%collision%substeps == 1)

    call load_ok('one key set', '&lbm tau = 0.8 /', cfg)
    call check('the key set changes, the others keep defaults', same(cfg%lbm%tau, 0.8_wp) .and. &
               same(cfg%lbm%dx, 0.004_wp) .and. same(cfg%domain%width, 2.0_wp))
  end subroutine test_defaults

  subroutine test_value_forms()
    type(config_t) :: cfg
    call load_ok('real written 1', '&inlet velocity = 1 /', cfg)
    call check('real 1 reads as 1.0', same(cfg%inlet%velocity, 1.0_wp))
    call load_ok('real written 1.5', '&inlet velocity = 1.5 /', cfg)
    call check('real 1.5', same(cfg%inlet%velocity, 1.5_wp))
    call load_ok('real written 1e-3', '&inlet velocity = 1e-3 /', cfg)
    call check('real 1e-3', same(cfg%inlet%velocity, 1.0e-3_wp))
    call load_ok('real written 1.5d0', '&inlet velocity = 1.5d0 /', cfg)
    call check('real 1.5d0', same(cfg%inlet%velocity, 1.5_wp))
    call load_ok('real written -2.5E+2', '&inlet velocity = -2.5E+2 /', cfg)
    call check('real -2.5E+2', same(cfg%inlet%velocity, -250.0_wp))
    call load_ok('real written .25', '&inlet velocity = .25 /', cfg)
    call check('real .25', same(cfg%inlet%velocity, 0.25_wp))
    call load_ok('integer', '&run steps = 42 /', cfg)
    call check('integer 42', cfg%run%steps == 42)
  end subroutine test_value_forms

  subroutine test_arrays_strings_logicals()
    type(config_t) :: cfg
    call load_ok('array as list', '&fluid body_force = 1.5, -2 /', cfg)
    call check('array list fills both elements', &
               all(same(cfg%fluid%body_force, [1.5_wp, -2.0_wp])))
    call load_ok('array list separated by blanks', '&fluid body_force = 3 4 /', cfg)
    call check('blank-separated list', all(same(cfg%fluid%body_force, [3.0_wp, 4.0_wp])))
    call load_ok('array element', '&fluid body_force(2) = -9.5 /', cfg)
    call check('element 2 set, element 1 default', &
               all(same(cfg%fluid%body_force, [0.0_wp, -9.5_wp])))
    call load_ok('array null value', '&fluid body_force = 7, 8'//NL//'body_force = , 2 /', cfg)
    call check('a null value leaves the element', &
               all(same(cfg%fluid%body_force, [7.0_wp, 2.0_wp])))

    call load_ok('string in single quotes', '&output dir = ''runs/a b'' /', cfg)
    call check('single-quoted string with a blank', cfg%output%dir == 'runs/a b')
    call load_ok('string in double quotes', '&output dir = "it''s" /', cfg)
    call check('double-quoted string with a quote', cfg%output%dir == 'it''s')
    call load_ok('doubled quote', '&output dir = ''it''''s'' /', cfg)
    call check('doubled quote inside a string', cfg%output%dir == 'it''s')
    call load_ok('string with ! and /', '&output dir = ''a!b/c'' /', cfg)
    call check('! and / inside a string are text', cfg%output%dir == 'a!b/c')
    call load_ok('choice in capitals', '&lbm collision = ''BGK'' /', cfg)
    call check('choice compared without case', cfg%lbm%collision == 'bgk')

    call load_ok('logical .true.', '&output overwrite = .true. /', cfg)
    call check('logical .true.', cfg%output%overwrite)
    call load_ok('logical F', '&output overwrite = .true., overwrite = F /', cfg)
    call check('logical F (and a repeated key: last wins)', (.not. cfg%output%overwrite))
    call load_ok('logical T', '&output overwrite = T /', cfg)
    call check('logical T', cfg%output%overwrite)
    call load_ok('logical true', '&output overwrite = true /', cfg)
    call check('logical true', cfg%output%overwrite)
    call load_ok('logical .FALSE.', '&output overwrite = true, overwrite = .FALSE. /', cfg)
    call check('logical .FALSE.', (.not. cfg%output%overwrite))
    call load_ok('logical false', '&output overwrite = true, overwrite = false /', cfg)
    call check('logical false', (.not. cfg%output%overwrite))
  end subroutine test_arrays_strings_logicals

  subroutine test_syntax_forms()
    type(config_t) :: cfg
    character(len=:), allocatable :: text
    character(len=*), parameter :: CR = achar(13)
    text = '! a scene'//NL// &
           '&LBM  TAU = 0.7,  ! relaxation'//NL// &
           '      Dx = 0.002'//NL// &
           '      ! tau = 0.9 is a comment'//NL// &
           '/'//NL// &
           '&domain sides = ''periodic'', width = 1.0 &end'//CR//NL// &
           '&fluid'//CR//NL//'  viscosity = 0.02'//CR//NL//'/'//CR//NL
    call load_ok('upper case, comments, &end, CRLF', text, cfg)
    call check('names are case-insensitive', &
               same(cfg%lbm%tau, 0.7_wp) .and. same(cfg%lbm%dx, 0.002_wp))
    call check('comment lines are ignored', same(cfg%lbm%tau, 0.7_wp))
    call check('&end closes a group', cfg%domain%sides == 'periodic' .and. &
               same(cfg%domain%width, 1.0_wp))
    call check('CR LF line ends', same(cfg%fluid%viscosity, 0.02_wp))
    call load_ok('groups repeated, keys given twice', &
                 '&lbm tau = 0.7 / &lbm tau = 0.9, tau = 0.75 /', cfg)
    call check('the last value of a repeated key wins', same(cfg%lbm%tau, 0.75_wp))
  end subroutine test_syntax_forms

  subroutine test_overrides()
    type(config_t) :: cfg
    call load_ok('overrides', '&lbm tau = 0.8 / &output dir = ''a'' /', cfg, &
                 [character(len=40) :: 'lbm.tau=0.7', 'fluid.body_force(1)=2.5', &
                  'output.dir=/tmp/x', 'LBM.Collision=bgk', 'output.overwrite=T'])
    call check('--set wins over the file', same(cfg%lbm%tau, 0.7_wp))
    call check('--set of an array element', all(same(cfg%fluid%body_force, [2.5_wp, 0.0_wp])))
    call check('--set of an unquoted string', cfg%output%dir == '/tmp/x')
    call check('--set of a choice, any case', cfg%lbm%collision == 'bgk')
    call check('--set of a logical', cfg%output%overwrite)
    call load_ok('override of a whole array', '', cfg, [character(len=40) :: &
                                                        'fluid.body_force=1,2'])
    call check('--set of a list', all(same(cfg%fluid%body_force, [1.0_wp, 2.0_wp])))
    call load_ok('override of a quoted string', '', cfg, &
                 [character(len=40) :: 'output.dir=''/tmp/a b''', 'lbm.tau=0.6', 'lbm.tau=0.9'])
    call check('--set strips quotes', cfg%output%dir == '/tmp/a b')
    call check('later --set wins', same(cfg%lbm%tau, 0.9_wp))
    ! Ranges are checked after the overrides: an override may mend a file value.
    call load_ok('override mends a bad file value', '&lbm tau = 0.4 /', cfg, &
                 [character(len=40) :: 'lbm.tau=0.7'])
  end subroutine test_overrides

  subroutine test_round_trip()
    type(config_t) :: cfg, back
    character(len=:), allocatable :: text, text2, err
    call load_ok('a configuration of non-default values', &
                 '&domain width = 1.0, height = 3.0,'// &
                 ' lower = ''velocity'', upper = ''outflow'' /'//NL// &
                 '&fluid density = 1.3, viscosity = 0.035,'// &
                 ' body_force = 1.0e-20, -3.3333333333333335 /'//NL// &
                 '&lbm dx = 0.01, tau = 0.8, collision = ''bgk'', s_q = 1.2 /'//NL// &
                 '&inlet velocity = -0.7, profile = ''uniform'', ramp_time = 0.1 /'//NL// &
                 '&run steps = 17, t_ref = 0.3, progress_every = 0, mach_limit = 0.2 /'//NL// &
                 '&output dir = ''out/it''''s'', field_interval = 0.01, overwrite = T /'//NL// &
                 '&particles count = 3, diameter = 0.25, 0.125, 0.3, x = 0.3, 0.7, 0.5,'// &
                 ' y = 1.0, 2.0, 2.6, omega(3) = -1.5, motion = ''free'', ''fixed'','// &
                 ' ''prescribed'', gravity = 981.5 /'//NL// &
                 '&coupling bounce_back = ''bfl'', momentum = ''galilean'' /'//NL// &
                 '&collision stiffness = 2.5e-8, range = 0.5, substeps = 4 /', cfg)
    call config_to_namelist(cfg, text)
    call config_load(back, text, FILE, none, err)
    call check('config_to_namelist text is read back without error', len(err) == 0)
    call check('round trip keeps reals exactly', &
               same(back%fluid%viscosity, cfg%fluid%viscosity) .and. &
               all(same(back%fluid%body_force, cfg%fluid%body_force)) .and. &
               same(back%inlet%velocity, -0.7_wp) .and. same(back%run%t_ref, 0.3_wp))
    call check('round trip keeps strings, choices, logicals, integers', &
               back%output%dir == 'out/it''s' .and. back%domain%lower == 'velocity' .and. &
               back%lbm%collision == 'bgk' .and. back%output%overwrite .and. back%run%steps == 17)
    call check('round trip keeps particle arrays, choices and the other new groups', &
               back%particles%count == 3 .and. &
               all(same(back%particles%diameter, cfg%particles%diameter)) .and. &
               all(same(back%particles%omega, cfg%particles%omega)) .and. &
               same(back%particles%omega(3), -1.5_wp) .and. &
               size(back%particles%motion) == 3 .and. &
               all(back%particles%motion == [character(len=16) :: 'free', 'fixed', &
                                             'prescribed']) .and. &
               same(back%particles%gravity, 981.5_wp) .and. &
               back%coupling%bounce_back == 'bfl' .and. back%coupling%momentum == 'galilean' .and. &
               same(back%collision%stiffness, 2.5e-8_wp) .and. back%collision%substeps == 4)
    call config_to_namelist(back, text2)
    call check('round trip text is stable', text == text2)
    call check('namelist text has one commented line per key', &
               index(text, 'tau = 0.8') > 0 .and. index(text, 'default: 0.65') > 0 .and. &
               index(text, 'allowed: 0.5 < tau <= 10') > 0 .and. index(text, '[cm]') > 0)
    call check('an array of choices is one line of quoted values', &
               index(text, 'motion = ''free'', ''fixed'', ''prescribed'' !') > 0)
  end subroutine test_round_trip

  subroutine test_cross_checks_accept()
    type(config_t) :: cfg
    call load_ok('periodic ends together', &
                 '&domain lower = ''periodic'', upper = ''periodic'' /', cfg)
    call load_ok('a velocity end with zero velocity (a moving wall at rest)', &
                 '&domain lower = ''velocity'', upper = ''outflow'' /', cfg)
    call load_ok('taylor_green in a periodic box', '&domain sides = ''periodic'', '// &
                 'lower = ''periodic'', upper = ''periodic'' /'// &
                 ' &initial flow = ''taylor_green'', velocity = 0.5 /', cfg)
    call load_ok('three cells across', '&domain width = 0.012 / &lbm dx = 0.004 /', cfg)
    call load_ok('t_end shorter than t_end/dt but steps given', &
                 '&run t_end = 1e-12, steps = 5 /', cfg)
  end subroutine test_cross_checks_accept

  subroutine test_derive_lattice()
    type(config_t) :: cfg
    type(lattice_params_t) :: lp
    character(len=:), allocatable :: err
    real(wp) :: nu_lb, dt, s_nu, s_q, u_peak
    call load_ok('lattice scene', '&fluid body_force = 0, -2 / &inlet velocity = 0.5 /', cfg)
    call derive_lattice(cfg, lp, err)
    call check('derive_lattice accepts a valid config', len(err) == 0)
    call check('no particles: particles_on false, cells_per_diameter 0', &
               (.not. lp%particles_on) .and. same(lp%cells_per_diameter, 0.0_wp))
    ! docs/model.md E3 by hand: nu_lb = (tau - 1/2)/3, dt = nu_lb dx^2 / (mu/rho).
    nu_lb = (0.65_wp - 0.5_wp)/3.0_wp
    dt = nu_lb*0.004_wp**2/(0.01_wp/1.0_wp)
    s_nu = 1.0_wp/0.65_wp
    s_q = 8.0_wp*(2.0_wp - s_nu)/(8.0_wp - s_nu)
    call check('nu_lb = (tau - 1/2)/3', close_to(lp%nu_lb, nu_lb))
    call check('dt = nu_lb dx^2 / nu (8e-5 s)', close_to(lp%dt, dt) .and. close_to(dt, 8.0e-5_wp))
    call check('nx = width/dx = 500, ny = height/dx = 1250', lp%nx == 500 .and. lp%ny == 1250)
    call check('steps = t_end/dt = 12500', lp%steps == 12500)
    call check('MRT rates 0, s_e, s_eps, 0, s_q, 0, s_q, 1/tau, 1/tau (E3 rule for s_q)', &
               same(lp%s(0), 0.0_wp) .and. same(lp%s(3), 0.0_wp) .and. same(lp%s(5), 0.0_wp) .and. &
               close_to(lp%s(1), 1.1_wp) .and. close_to(lp%s(2), 1.25_wp) .and. &
               close_to(lp%s(4), s_q) .and. close_to(lp%s(6), s_q) .and. &
               close_to(lp%s(7), s_nu) .and. close_to(lp%s(8), s_nu))
    call check('force_lb = g dt^2/dx', same(lp%force_lb(1), 0.0_wp) .and. &
               close_to(lp%force_lb(2), -2.0_wp*dt**2/0.004_wp))
    call check('u_in_lb = U dt/dx', close_to(lp%u_in_lb, 0.5_wp*dt/0.004_wp))
    ! Largest of the inlet speed and the Poiseuille peak g W^2/(8 nu) in lattice units.
    u_peak = 2.0_wp*dt**2/0.004_wp*500.0_wp**2/(8.0_wp*nu_lb)
    call check('u_scale_lb is the largest expected speed', &
               close_to(lp%u_scale_lb, max(0.5_wp*dt/0.004_wp, u_peak)))
    call check('mach = u_scale / sqrt(1/3)', close_to(lp%mach, lp%u_scale_lb*sqrt(3.0_wp)))
    call check('reynolds = U W / nu', &
               close_to(lp%reynolds, lp%u_scale_lb*0.004_wp/dt*2.0_wp/0.01_wp))

    call load_ok('bgk with field output', '&lbm collision = ''bgk'', tau = 0.8 / '// &
                 '&output field_interval = 0.01 /', cfg)
    call derive_lattice(cfg, lp, err)
    dt = (0.3_wp/3.0_wp)*0.004_wp**2/0.01_wp
    call check('BGK: every rate 1/tau (E4)', all(abs(lp%s - 1.0_wp/0.8_wp) < 1.0e-15_wp))
    call check('field_every = field_interval/dt', lp%field_every == nint(0.01_wp/dt))

    call load_ok('lattice scene with particles', '&particles count = 2, '// &
                 'diameter = 0.2, 0.1, x = 1.0, 1.0, y = 3.0, 2.0 /', cfg)
    call derive_lattice(cfg, lp, err)
    call check('particles_on with count > 0', len(err) == 0 .and. lp%particles_on)
    call check('cells_per_diameter = smallest used diameter/dx = 0.1/0.004 = 25', &
               close_to(lp%cells_per_diameter, 25.0_wp))

    cfg%lbm%tau = 0.3_wp
    call config_validate(cfg, err)
    call expect_parts('config_validate refuses a value changed in code', err, &
                      [character(len=20) :: '&lbm', 'tau', '0.3'])
    call derive_lattice(cfg, lp, err)
    call check('derive_lattice refuses an invalid config', len(err) > 0)
  end subroutine test_derive_lattice

  !> config_load converts to lattice units once and returns that result: for a scene whose
  !! &pair, &window, cells_per_diameter and mach are expanded first, the parameters it returns
  !! equal, bit for bit, those derive_lattice derives from the loaded configuration, with the
  !! same warnings. Bugs caught: parameters returned from the configuration before expansion
  !! (dx, tau, height, particles), from a copy the checks changed, or left unset.
  subroutine test_load_returns_lattice()
    type(config_t) :: cfg
    type(lattice_params_t) :: lp, again
    character(len=:), allocatable :: err, warnings, warnings_again
    call config_load(cfg, '&pair gamma = 2, d1 = 0.2, y_upper = 15.0 / &lbm cells_per_diameter'// &
                     ' = 8, mach = 0.05 / &window enabled = T / &run steps = 10 /', FILE, none, &
                     err, warnings, lp)
    call check('expanded scene loads', len(err) == 0)
    call derive_lattice(cfg, again, err, warnings_again)
    call check('the loaded configuration is valid as it stands', len(err) == 0)
    call check('load returns the lattice of the expanded scene: dx, dt, tau, rates', &
               same(lp%dx, again%dx) .and. same(lp%dt, again%dt) .and. &
               same(lp%tau, again%tau) .and. all(same(lp%s, again%s)))
    call check('.. cells, steps, velocity scale', lp%nx == again%nx .and. &
               lp%ny == again%ny .and. lp%steps == again%steps .and. &
               same(lp%u_scale_lb, again%u_scale_lb) .and. lp%steps == 10)
    call check('.. the two particles in lattice units', size(lp%particles%y) == 2 .and. &
               all(same(lp%particles%y, again%particles%y)) .and. &
               all(same(lp%particles%r, again%particles%r)))
    call check('.. tau is the one lbm.mach set, dx the one cells_per_diameter set', &
               same(lp%tau, cfg%lbm%tau) .and. same(lp%dx, cfg%lbm%dx) .and. &
               .not. same(cfg%lbm%tau, 0.65_wp))
    call check('.. and the same warnings', warnings == warnings_again)
  end subroutine test_load_returns_lattice

  subroutine test_command_line()
    type(cli_t) :: cli
    character(len=:), allocatable :: err
    call parse_arguments([character(len=40) :: 'input/case1.nml', '--set', 'lbm.tau=0.7', &
                          '--set=fluid.body_force(1)=2', '--check'], cli, err)
    call check('command line: file, --set x, --set=x, --check', len(err) == 0 .and. &
               cli%nml_file == 'input/case1.nml' .and. size(cli%overrides) == 2 .and. &
               cli%check .and. .not. cli%print_defaults)
    call check('command line: overrides in order', cli%overrides(1) == 'lbm.tau=0.7' .and. &
               cli%overrides(2) == 'fluid.body_force(1)=2')
    call parse_arguments([character(len=20) :: '--print-defaults'], cli, err)
    call check('command line: --print-defaults needs no file', len(err) == 0 .and. &
               cli%print_defaults)
    call parse_arguments([character(len=20) :: '--help'], cli, err)
    call check('command line: --help', len(err) == 0 .and. cli%help)
    call parse_arguments([character(len=20) :: '--version'], cli, err)
    call check('command line: --version', len(err) == 0 .and. cli%version)
    call parse_arguments([character(len=20) :: 'a.nml', '--frobnicate'], cli, err)
    call expect_parts('command line: unknown option lists the options', err, &
                      [character(len=20) :: '--frobnicate', '--set', '--check', &
                       '--print-defaults', '--help', '--version'])
    call parse_arguments([character(len=20) :: '--check'], cli, err)
    call expect_parts('command line: no file', err, [character(len=20) :: 'no namelist file'])
    call parse_arguments([character(len=20) :: 'a.nml', '--set'], cli, err)
    call expect_parts('command line: --set without value', err, [character(len=20) :: '--set'])
    call parse_arguments([character(len=20) :: 'a.nml', 'b.nml'], cli, err)
    call expect_parts('command line: two files', err, [character(len=20) :: 'a.nml', 'b.nml'])
  end subroutine test_command_line

  subroutine test_errors()
    character(len=:), allocatable :: text, err
    character(len=*), parameter :: PERIODIC = '&domain sides = ''periodic'', '// &
                                   'lower = ''periodic'', upper = ''periodic'' /'

    call expect_error('error: unknown key names group, key, value, suggestion and keys', &
                      '&lbm'//NL//'  taux = 0.7 /', &
                      [character(len=40) :: 'input/test.nml:2:', '&lbm', 'taux', '0.7', &
                       'did you mean ''tau''', 'collision'])
    call expect_error('error: unknown group names it, suggests one, lists the groups', &
                      '&lbn tau = 0.7 /', &
                      [character(len=40) :: 'input/test.nml:1:', '&lbn', 'tau', '0.7', &
                       'did you mean &lbm', '&domain', '&output'])
    call expect_error('error: value not a real number', '&lbm tau = abc /', &
                      [character(len=40) :: 'input/test.nml:1:', '&lbm', 'tau', 'abc', &
                       'not a real number', '0.5 < tau <= 10'])
    call expect_error('error: a repeat count beyond a scalar', '&lbm tau = 2*0.7 /', &
                      [character(len=40) :: '&lbm', 'tau', '2*0.7', 'too many values', &
                       'tau takes 1 value'])
    call expect_error('error: string for a real', '&lbm tau = ''0.7'' /', &
                      [character(len=40) :: '&lbm', 'tau', '''0.7''', 'not a real number'])
    call expect_error('error: value not an integer', '&run steps = 1.5 /', &
                      [character(len=40) :: '&run', 'steps', '1.5', 'not an integer'])
    call expect_error('error: value not a logical', '&output overwrite = yes /', &
                      [character(len=40) :: '&output', 'overwrite', 'yes', 'not a logical', &
                       '.true. or .false.'])
    call expect_error('error: value out of range names line and range', &
                      '&fluid'//NL//'/'//NL//'&lbm'//NL//'  tau = 0.4'//NL//'/', &
                      [character(len=40) :: 'input/test.nml:4:', '&lbm tau = 0.4', &
                       'out of range', 'allowed: 0.5 < tau <= 10', 'relaxation time'])
    call expect_error('error: integer out of range', '&run guard_every = 0 /', &
                      [character(len=40) :: '&run', 'guard_every', '= 0', 'guard_every >= 1'])
    call expect_error('error: s_q is 0 or in (0, 2)', '&lbm s_q = 2.0 /', &
                      [character(len=40) :: '&lbm', 's_q', '2.0', 's_q = 0 or 0 < s_q < 2'])
    call expect_error('error: choice not in the list', '&lbm collision = ''trt'' /', &
                      [character(len=40) :: 'input/test.nml:1:', '&lbm', 'collision', &
                       '''trt''', '''mrt'', ''bgk'''])
    call expect_error('error: array index out of range', '&fluid body_force(3) = 1.0 /', &
                      [character(len=40) :: 'input/test.nml:1:', '&fluid', 'body_force(3)', &
                       '1.0', 'index 3', '2 elements'])
    call expect_error('error: index on a scalar', '&lbm tau(1) = 0.7 /', &
                      [character(len=40) :: '&lbm', 'tau(1)', '0.7', 'not an array'])
    call expect_error('error: too many values', '&fluid body_force = 1, 2, 3 /', &
                      [character(len=40) :: '&fluid', 'body_force', '1, 2, 3', 'too many'])
    call expect_error('error: --set without a value', '', &
                      [character(len=40) :: '--set lbm.tau=', '&lbm', 'tau', 'no value', &
                       '0.5 < tau <= 10'], [character(len=40) :: 'lbm.tau='])
    call expect_error('error: string too long', '&lbm collision = ''a_very_long_model'' /', &
                      [character(len=40) :: '&lbm', 'collision', 'a_very_long_model', 'too long'])
    call expect_error('error: group not closed', '&lbm tau = 0.7', &
                      [character(len=40) :: 'input/test.nml:1:', '&lbm', 'not closed'])
    call expect_error('error: group not closed before the next', '&lbm tau = 0.7 &run /', &
                      [character(len=40) :: '&lbm', '&run', 'not closed'])
    call expect_error('error: text outside a group', 'tau = 0.7', &
                      [character(len=40) :: 'input/test.nml:1:', 'tau', 'outside a group'])
    call expect_error('error: string not closed', '&output'//NL//'dir = ''abc /', &
                      [character(len=40) :: 'input/test.nml:2:', 'abc', 'not closed'])

    ! Cross-key rules.
    call expect_error('error: lower periodic without upper', &
                      '&domain lower = ''periodic'' /', &
                      [character(len=40) :: 'input/test.nml:1:', '&domain', 'lower', &
                       '''periodic''', 'upper', '''wall'''])
    call expect_error('error: taylor_green needs periodic sides and ends', &
                      '&initial flow = ''taylor_green'' /', &
                      [character(len=40) :: '&initial', 'flow', '''taylor_green''', 'sides', &
                       'periodic'])
    call expect_error('error: taylor_green with periodic ends but wall sides', &
                      PERIODIC//' &domain sides = ''wall'' / &initial flow = ''taylor_green'' /', &
                      [character(len=40) :: '&initial', 'flow', 'sides = ''wall'''])
    call expect_error('error: fewer than 3 cells across', &
                      '&domain width = 0.008 / &lbm dx = 0.004 /', &
                      [character(len=40) :: '&domain width = 0.008', '&lbm dx = 0.004', 'nx', &
                       '= 2 cells', 'nx >= 3'])
    call expect_error('error: fewer than 3 cells along', &
                      '&domain height = 0.004 / &lbm dx = 0.004 /', &
                      [character(len=40) :: '&domain height = 0.004', '&lbm dx = 0.004', 'ny', &
                       '= 1 cells'])
    call expect_error('error: width not a whole number of cells', '&lbm dx = 0.003 /', &
                      [character(len=40) :: 'input/test.nml:1:', '&domain width = 2.0', &
                       '&lbm dx = 0.003', '666.66', 'not a whole number', 'dx = width/n'])
    call expect_error('error: t_end gives no time step', '&run t_end = 1e-9 /', &
                      [character(len=40) :: 'input/test.nml:1:', '&run', 't_end', '1.0e-9', &
                       '0 time steps', 'steps >= 1'])

    ! Overrides: the message names the option and the file.
    call expect_error('error: override out of range', '&lbm tau = 0.7 /', &
                      [character(len=40) :: 'input/test.nml', '--set lbm.tau=0.4', &
                       '&lbm tau = 0.4', '0.5 < tau <= 10'], [character(len=40) :: 'lbm.tau=0.4'])
    call expect_error('error: override of an unknown key', '', &
                      [character(len=40) :: 'input/test.nml', '--set lbm.taux=1', 'taux', &
                       'did you mean ''tau'''], [character(len=40) :: 'lbm.taux=1'])
    call expect_error('error: override of an unknown group', '', &
                      [character(len=40) :: '--set lbn.tau=1', '&lbn', 'tau', &
                       'did you mean &lbm'], &
                      [character(len=40) :: 'lbn.tau=1'])
    call expect_error('error: override not a number', '', &
                      [character(len=40) :: '--set run.steps=many', '&run', 'steps', 'many', &
                       'not an integer'], [character(len=40) :: 'run.steps=many'])
    call expect_error('error: override without a group', '', &
                      [character(len=40) :: '--set tau=0.7', 'group.key=value'], &
                      [character(len=40) :: 'tau=0.7'])

    call read_text_file('/nonexistent/dir/scene.nml', text, err)
    call expect_parts('error: missing namelist file', err, &
                      [character(len=60) :: 'cannot open namelist file ''/nonexistent/', &
                       'scene.nml'': no such file'])
  end subroutine test_errors

  ! ---------------------------------------------------------------- particles

  subroutine test_particle_keys()
    type(config_t) :: cfg
    call load_ok('particle arrays as lists', '&particles count = 2, diameter = 0.2, 0.1,'// &
                 ' density = 1.5, 2.5, x = 1.0, 1.2, y = 4.2, 3.8 /', cfg)
    call check('real lists fill elements 1 and 2 of arrays of count = 2 elements', &
               cfg%particles%count == 2 .and. size(cfg%particles%u) == 2 .and. &
               all(same(cfg%particles%diameter, [0.2_wp, 0.1_wp])) .and. &
               all(same(cfg%particles%density, [1.5_wp, 2.5_wp])) .and. &
               all(same(cfg%particles%x, [1.0_wp, 1.2_wp])) .and. &
               all(same(cfg%particles%y, [4.2_wp, 3.8_wp])) .and. &
               all(same(cfg%particles%u, 0.0_wp)))
    call load_ok('particle array element', '&particles count = 2, y = 3, 2, diameter(2) = 0.1,'// &
                 ' motion(2) = ''fixed'' /', cfg)
    call check('diameter(2) set, diameter(1) default', &
               all(same(cfg%particles%diameter(1:2), [0.2_wp, 0.1_wp])))
    call check('motion(2) = ''fixed'' sets element 2 only', &
               cfg%particles%motion(2) == 'fixed' .and. cfg%particles%motion(1) == 'free' .and. &
               all(cfg%particles%motion(3:) == 'free'))
    call load_ok('list of choices, quoted and not, any case', '&particles count = 3,'// &
                 ' y = 1, 2, 3, motion = ''PRESCRIBED'', fixed, ''Free'' /', cfg)
    call check('list of choices fills elements 1 to 3, lower case', &
               all(cfg%particles%motion(1:3) == [character(len=16) :: 'prescribed', 'fixed', &
                                                 'free']))
    call load_ok('null value in a list of choices', '&particles motion = fixed, fixed'//NL// &
                 'motion = , ''prescribed'' /', cfg)
    call check('a null value leaves that choice unchanged', &
               cfg%particles%motion(1) == 'fixed' .and. cfg%particles%motion(2) == 'prescribed')
    call load_ok('element 16 of each particle array', '&particles diameter(16) = 0.5,'// &
                 ' motion(16) = ''prescribed'', omega(16) = 2 /', cfg)
    call check('the last element is reachable', same(cfg%particles%diameter(16), 0.5_wp) .and. &
               cfg%particles%motion(16) == 'prescribed' .and. same(cfg%particles%omega(16), 2.0_wp))
    call load_ok('coupling and collision keys', '&coupling bounce_back = ''halfway'','// &
                 ' momentum = ''galilean'' / &collision stiffness = 2e-7,'// &
                 ' stiffness_overlap = 3e-8, range = 0, substeps = 1000 /'// &
                 ' &particles gravity = 0 /', cfg)
    call check('coupling choices read', cfg%coupling%bounce_back == 'halfway' .and. &
               cfg%coupling%momentum == 'galilean')
    call check('collision values read (range 0 and substeps 1000 are allowed)', &
               same(cfg%collision%stiffness, 2.0e-7_wp) .and. &
               same(cfg%collision%stiffness_overlap, 3.0e-8_wp) .and. &
               same(cfg%collision%range, 0.0_wp) .and. cfg%collision%substeps == 1000)
    call check('gravity 0 is allowed', same(cfg%particles%gravity, 0.0_wp))

    call load_ok('--set of particle elements and lists', '&particles count = 3, y = 1, 2, 3 /', &
                 cfg, [character(len=48) :: 'particles.motion=fixed,''prescribed''', &
                       'particles.motion(3)=PRESCRIBED', 'particles.diameter(2)=0.15', &
                       'particles.x=0.5,1.5', 'coupling.bounce_back=bfl'])
    call check('--set of a list of choices (quotes optional)', &
               all(cfg%particles%motion(1:3) == [character(len=16) :: 'fixed', 'prescribed', &
                                                 'prescribed']))
    call check('--set of a real element and a real list', &
               all(same(cfg%particles%diameter(1:3), [0.2_wp, 0.15_wp, 0.2_wp])) .and. &
               all(same(cfg%particles%x(1:3), [0.5_wp, 1.5_wp, 1.0_wp])))
    call check('--set of a choice of &coupling', cfg%coupling%bounce_back == 'bfl')
  end subroutine test_particle_keys

  !> The size of the particle arrays follows the input: particles.count when given above 0,
  !! else the highest element any particle array is given; a pair scene at least 2; always at
  !! least 1. Bugs caught: arrays left at a fixed size, count ignored when a larger index is
  !! given, an index above count accepted or refused without the range (1) to (count), the
  !! pair writing past the arrays, particles_allocate losing the values it keeps.
  subroutine test_particle_sizing()
    type(config_t) :: cfg
    type(particles_cfg_t) :: p
    type(particle_cfg_t) :: d !! its initialisers: the defaults of one particle
    character(len=*), parameter :: THREE = '&particles count = 3, x = 0.5, 1.0, 1.5, '// &
                                   'y = 2, 2, 2 /'
    call load_ok('count = 3', THREE, cfg)
    call check('count = 3: arrays of 3 elements', size(cfg%particles%x) == 3 .and. &
               size(cfg%particles%diameter) == 3 .and. size(cfg%particles%motion) == 3)
    call load_ok('count = 3 and fewer values', '&particles count = 3, x = 0.5, 1.0, 1.5, '// &
                 'y = 2 /'//NL//'&particles y(2:3) = 3, 4 /', cfg)
    call check('count = 3 with values for fewer: still 3 elements, the rest defaults', &
               size(cfg%particles%omega) == 3 .and. all(same(cfg%particles%omega, 0.0_wp)))
    call load_ok('count by --set', '&particles x = 0.5, 1.0, 1.5, y = 2, 2, 2 /', cfg, &
                 [character(len=20) :: 'particles.count=3'])
    call check('count = 3 by --set: arrays of 3 elements', size(cfg%particles%v) == 3)
    call load_ok('no count: highest element', '&particles omega(7) = 1 /', cfg)
    call check('count 0: arrays sized by the highest element given to any array (7)', &
               cfg%particles%count == 0 .and. size(cfg%particles%diameter) == 7 .and. &
               size(cfg%particles%motion) == 7 .and. same(cfg%particles%omega(7), 1.0_wp))
    call load_ok('count 0 given, a list', '&particles count = 0, y = 1, 2, 3, 4 /', cfg)
    call check('count = 0 given: the longest list sizes the arrays (4)', &
               size(cfg%particles%x) == 4)
    call load_ok('a pair scene', '&pair gamma = 1.5, y_upper = 3 /', cfg)
    call check('a pair scene: arrays of at least 2 elements', &
               size(cfg%particles%diameter) >= 2 .and. size(cfg%particles%motion) >= 2)
    call expect_error('error: an index above count', THREE//'&particles x(4) = 1 /', &
                      [character(len=60) :: 'input/test.nml:1:', '&particles', 'x(4)', &
                       'index 4', 'x(1) to x(3)', 'particles.count'])
    call expect_error('error: a list longer than count', '&particles count = 2, '// &
                      'diameter = 0.2, 0.1, 0.02 /', &
                      [character(len=60) :: 'input/test.nml:1:', '&particles', 'diameter', &
                       'too many values (3)', 'diameter takes 2 values', 'particles.count'])
    call expect_error('error: an index above count by --set', THREE, &
                      [character(len=60) :: '--set', 'particles.y(5)', 'index 5', &
                       'y(1) to y(3)'], [character(len=20) :: 'particles.y(5)=1'])
    ! a configuration built in code: particles_allocate keeps elements 1..min(old, new)
    call particles_allocate(p, 2)
    p%x = [0.5_wp, 1.5_wp]
    p%motion(2) = 'fixed'
    call particles_allocate(p, 3)
    call check('particles_allocate keeps the values and gives new elements the defaults', &
               size(p%x) == 3 .and. all(same(p%x, [0.5_wp, 1.5_wp, 1.0_wp])) .and. &
               all(p%motion == [character(len=16) :: 'free', 'fixed', 'free']) .and. &
               all(same(p%diameter, 0.2_wp)) .and. all(same(p%density, 1.01_wp)))
    call check('.. the defaults of one particle, particle_cfg_t', same(p%y(3), d%y) .and. &
               same(p%u(3), d%u) .and. same(p%v(3), d%v) .and. same(p%omega(3), d%omega) .and. &
               same(p%diameter(3), d%diameter) .and. p%motion(3) == d%motion)
    call particles_allocate(p, 1)
    call check('particles_allocate shrinks to the first elements', &
               size(p%x) == 1 .and. same(p%x(1), 0.5_wp) .and. size(p%motion) == 1)
    call check('MAX_PARTICLES is the checkpoint limit, 10^6', MAX_PARTICLES == 1000000)
  end subroutine test_particle_sizing

  !> The particle arrays are sized while the input is read, in one read: a registry built
  !! with grow gives the arrays of the configuration more elements as the parser reaches them
  !! (its resize hook), and config_load sizes them to the final count after the one read.
  !! Bugs caught: a value beyond the arrays refused or written past them, the keys left bound
  !! to the arrays a resize freed (values lost, or a choice array written to freed memory),
  !! growth by one element at a time (10^5 particles quadratic), the final size not that of
  !! the input (x(7), count, a pair, --set), the default column of cfg%given not as long as
  !! the arrays, an input the one read takes but the final size does not (it is refused as
  !! before, with that size in the message), and a count or pair after an item that fits one
  !! size only (x(::-1)) leaving the particles beyond the arrays.
  subroutine test_particle_growth()
    type(config_t), target :: c
    type(config_t) :: cfg
    type(registry_t) :: reg
    type(particle_cfg_t) :: d !! its initialisers: the defaults of one particle
    character(len=:), allocatable :: err
    integer :: k
    ! the registry level: the arrays grow during the read, before any final sizing
    call config_registry(c, reg, grow=.true.)
    call check('grow: the arrays start with 1 element', size(c%particles%x) == 1)
    call parse_namelist(reg, '&particles x(1) = 0.5, motion(1) = ''fixed'' /'//NL// &
                        '&particles x(5) = 1.5, motion(9) = ''prescribed'' /', FILE, err)
    call check('grow: x(5) and motion(9) are read without an error', len(err) == 0)
    call check('grow: the arrays grew while reading, all alike, to hold element 9', &
               size(c%particles%x) >= 9 .and. size(c%particles%motion) == size(c%particles%x))
    call check('grow: the values before and after a resize are in the configuration', &
               same(c%particles%x(1), 0.5_wp) .and. same(c%particles%x(5), 1.5_wp) .and. &
               c%particles%motion(1) == 'fixed' .and. c%particles%motion(9) == 'prescribed')
    k = find_key(reg, 'particles', 'x')
    call check('grow: the keys are bound to the grown arrays', &
               reg%keys(k)%n == size(c%particles%x) .and. &
               associated(reg%keys(k)%ra, c%particles%x))
    call check('grow: the highest element given is noted (9)', reg%top == 9)
    ! twice the size at least: x(5) on 1 element gives 5, x(6) then 10, not 6
    call config_registry(c, reg, grow=.true.)
    call apply_override(reg, 'particles.x(5)=1', FILE, err)
    call apply_override(reg, 'particles.x(6)=2', FILE, err)
    call check('grow: the arrays grow geometrically, so n elements cost O(n) copies', &
               size(c%particles%x) == 10 .and. same(c%particles%x(6), 2.0_wp))
    call final_size(reg, 6)
    call check('final_size: the arrays get the final size, the values kept', &
               size(c%particles%x) == 6 .and. reg%keys(k)%n == 6 .and. &
               same(c%particles%x(5), 1.0_wp) .and. same(c%particles%x(6), 2.0_wp))
    call apply_override(reg, 'particles.x(7)=3', FILE, err)
    call check('final_size: the arrays grow no more, element 7 of 6 is an error', &
               index(err, 'index 7 is out of range; x has 6 elements') > 0)
    ! config_load: the final size is the input's, the elements not given at the defaults
    call load_ok('x(7) without count', '&particles x(7) = 1.5 /', cfg)
    call check('x(7) without count: 7 elements, elements 1..6 at the defaults', &
               size(cfg%particles%x) == 7 .and. size(cfg%particles%motion) == 7 .and. &
               all(same(cfg%particles%x(1:6), d%x)) .and. same(cfg%particles%x(7), 1.5_wp) &
               .and. all(same(cfg%particles%diameter, d%diameter)))
    call check('x(7): the default column of the input as read has 7 elements', &
               index(cfg%given, 'default: '//repeat('1.0, ', 6)//'1.0;') > 0 .and. &
               index(cfg%given, 'default: '//repeat('1.0, ', 7)) == 0)
    call load_ok('count above the highest element', '&particles count = 3, x = 0.5, 1.5,'// &
                 ' y = 2, 3 /', cfg)
    call check('count = 3 and 2 values: 3 elements, element 3 at the defaults', &
               size(cfg%particles%x) == 3 .and. size(cfg%particles%omega) == 3 .and. &
               same(cfg%particles%x(3), d%x) .and. same(cfg%particles%y(3), d%y) .and. &
               all(cfg%particles%motion == d%motion))
    call load_ok('a pair scene, no particle keys', '&pair gamma = 1.5, y_upper = 3 /', cfg)
    call check('a pair scene: exactly 2 elements', size(cfg%particles%diameter) == 2)
    call load_ok('--set particles.y(9)', '&particles x(2) = 0.5 /', cfg, &
                 [character(len=20) :: 'particles.y(9)=3.5'])
    call check('--set particles.y(9) = 3.5 grows the arrays to 9', &
               size(cfg%particles%y) == 9 .and. same(cfg%particles%y(9), 3.5_wp) .and. &
               same(cfg%particles%x(2), 0.5_wp) .and. same(cfg%particles%x(9), d%x))
    ! taken by a read into arrays that grow, refused at the final size, with it in the message
    call expect_error('a null beyond the final size', '&particles x = 1.0, 3* /', &
                      [character(len=60) :: 'x = 1.0, 3*', 'too many values (4, counting '// &
                       'repeats)', 'x takes 1 value (the particle arrays'])
    call expect_error('a section beyond the final size', '&particles x(1:9) = 1.0 /', &
                      [character(len=60) :: 'selects element 9', 'x has 1 element'])
    ! a bad element: the read goes past it, so that y(9) sizes the arrays for x(1:9)
    call expect_error('a bad element before the one that sizes the arrays', &
                      '&particles x(1:9) = 1.0, y(1) = abc, y(9) = 2.0 /', &
                      [character(len=60) :: '&particles y(1) = abc is not a real number'])
    ! x(::-1) selects element 1 of one element and none of more: the first read stops there,
    ! before a count or a pair that asks for more; the arrays get that size all the same
    call load_ok('x(::-1) of one element', '&particles x(::-1) = 5 /', cfg)
    call check('x(::-1) of one element sets x(1)', &
               size(cfg%particles%x) == 1 .and. same(cfg%particles%x(1), 5.0_wp))
    call expect_error('x(::-1) before a pair', '&particles x(::-1) = 5 /'//NL// &
                      '&pair gamma = 1.5, y_upper = 3 /', &
                      [character(len=60) :: 'x(::-1)', 'selects no element (from 1 to 2'])
    call expect_error('x(::-1) before count = 3', '&particles x(::-1) = 5, count = 3 /', &
                      [character(len=60) :: 'x(::-1)', 'selects no element (from 1 to 3'])
  end subroutine test_particle_growth

  subroutine test_particle_scenes_accept()
    type(config_t) :: cfg
    ! docs/model.md §7, case0_box: 2 x 8 cm, open ends, two equal disks D = 0.2 at (1, 7.2)
    ! and (1, 6.8).
    call load_ok('the case0_box scene', '&domain width = 2, height = 8, lower = ''velocity'','// &
                 ' upper = ''outflow'' / &lbm dx = 0.008 / &particles count = 2,'// &
                 ' x = 1, 1, y = 7.2, 6.8 /', cfg)
    ! docs/model.md §7, single: box 2 x 6 cm, D = 0.25, rho_p = 1.25, released at (1, 4).
    call load_ok('the single scene', '&domain height = 6 / &fluid viscosity = 0.1 /'// &
                 ' &particles count = 1, diameter = 0.25, density = 1.25, x = 1, y = 4 /', cfg)
    ! Centres exactly one contact distance apart: 4.0 - 3.85 = 0.15 = (0.2 + 0.1)/2, which in
    ! floating point comes out one rounding below the contact distance.
    call load_ok('two particles touching', '&particles count = 2, diameter = 0.2, 0.1,'// &
                 ' x = 1, 1, y = 4.0, 3.85 /', cfg)
    call load_ok('particles may overlap an open end', '&domain upper = ''outflow'' /'// &
                 ' &particles count = 1, y = 4.95 /', cfg)
    call load_ok('a particle just clear of the wall', '&particles count = 1, x = 0.1001 /', cfg)
    call load_ok('a scene without particles may keep unused values', '&particles y(2) = 1,'// &
                 ' x(3) = -5, diameter(4) = 0.001, motion(5) = ''fixed'', u(5) = 1 /', cfg)
    ! (a run short enough that the path stays in the channel: 0.1 s moves it by (0.1, -0.2) cm)
    call load_ok('prescribed particles keep any velocity', '&particles count = 1,'// &
                 ' motion = ''prescribed'', u = 1, v = -2, omega = 3 / &run t_end = 0.1 /', cfg)
    call load_ok('a prescribed path that passes a fixed particle', '&particles count = 2,'// &
                 ' motion = ''prescribed'', ''fixed'', x = 0.5, 1.5, y = 4, 2, v = -2 /'// &
                 ' &run t_end = 1.0 /', cfg)
    call load_ok('fixed particle at rest', '&particles count = 1, motion = ''fixed'' /', cfg)
  end subroutine test_particle_scenes_accept

  !> Fewer than 8 cells per diameter is a warning, not an error; 8 or more (and count = 0)
  !! gives none. dx = 0.004 cm throughout.
  subroutine test_particle_warnings()
    type(config_t) :: cfg
    type(lattice_params_t) :: lp
    character(len=:), allocatable :: err, warnings
    ! (t_end long enough for the pair's DKT pattern: no warning about the run's length)
    call config_load(cfg, '&particles count = 2, diameter = 0.2, 0.024, y = 2, 3 / '// &
                     '&run t_end = 10 /', FILE, none, err, warnings)
    call check('6 cells per diameter is accepted', len(err) == 0)
    call expect_parts('6 cells per diameter gives a warning naming key, value, dx and cells', &
                      warnings, [character(len=40) :: 'input/test.nml:1:', &
                                 '&particles diameter(2) = 0.024', '&lbm dx = 0.004', &
                                 '6.0 cells per diameter', 'fewer than 8', '0.003'])
    call check('one warning for one coarse particle', index(warnings, NL) == 0)
    call derive_lattice(cfg, lp, err, warnings)
    call check('derive_lattice returns the same warning', len(err) == 0 .and. &
               index(warnings, 'diameter(2) = 0.024') > 0)

    call config_load(cfg, '&particles count = 3, diameter = 0.016, 0.2, 0.03,'// &
                     ' y = 2, 3, 4 /', FILE, none, err, warnings)
    call check('exactly 4 cells per diameter is accepted', len(err) == 0)
    call check('two coarse particles: two warning lines, 1 and 3', &
               index(warnings, 'diameter(1) = 0.016') > 0 .and. &
               index(warnings, 'diameter(3) = 0.03') > 0 .and. &
               index(warnings, 'diameter(2)') == 0 .and. &
               index(warnings, NL) > index(warnings, 'diameter(1)') .and. &
               index(warnings, NL) < index(warnings, 'diameter(3)'))

    call config_load(cfg, '&particles count = 1, diameter = 0.032 /', FILE, none, err, warnings)
    call check('8 cells per diameter: no warning', len(err) == 0 .and. len(warnings) == 0)
    call config_load(cfg, '&particles diameter = 0.02 /', FILE, none, err, warnings)
    call check('unused coarse particles (count = 0): no warning', len(err) == 0 .and. &
               len(warnings) == 0)
    call config_load(cfg, '&particles count = 1, diameter = 0.024 / &run t_end = 1e-9 /', &
                     FILE, none, err, warnings)
    call check('with an error the warnings are empty', len(err) > 0 .and. len(warnings) == 0)
  end subroutine test_particle_warnings

  !> Keys in range whose derived quantities are not (dt, nu, the step count, a prescribed
  !! path over the run), and scene texts without any group. Each expected piece follows from
  !! the edit: the defaults give dt = 8e-5 s and t_end = 1 s; a particle of diameter 0.2 at
  !! x = 1 moving at u = -1 cm/s touches the wall at x = 0 after (1 - 0.1)/1 = 0.9 s; one at
  !! y = 4 moving at v = -2 cm/s touches a fixed one at y = 2 after (2 - 0.2)/2 = 0.9 s.
  subroutine test_derived_and_text_errors()
    character(len=:), allocatable :: err
    call expect_error('error: density 1e-320 gives an infinite nu', &
                      '&fluid density = 1e-320 /', [character(len=40) :: 'input/test.nml:1:', &
                                                    '&fluid', 'density = 1.0e-320', 'nu = ', &
                                                    'about 1.0e318', 'finite nu > 0'])
    call expect_error('error: viscosity 1e308 gives a subnormal dt', &
                      '&fluid viscosity = 1e308 / &run steps = 5 /', &
                      [character(len=40) :: 'input/test.nml:1:', 'viscosity = 1.0e308', &
                       'time step dt', 'allowed: 1.0e-12 s <= dt', 'make lbm.dx larger'])
    call expect_error('error: t_end beyond the step bound names t_end and the dt keys', &
                      '&run t_end = 1e6 /', [character(len=40) :: 'input/test.nml:1:', &
                                             '&run t_end = 1000000.0', 'at most 1000000000', &
                                             'raise lbm.tau', 'make lbm.dx larger'])
    call expect_error('error: steps beyond the bound', '&run steps = 2000000000 /', &
                      [character(len=40) :: 'input/test.nml:1:', 'steps = 2000000000', &
                       'steps <= 1000000000'])
    call expect_error('error: a prescribed path through the side wall', &
                      '&particles count = 1, motion = ''prescribed'', u = -1 /', &
                      [character(len=40) :: 'input/test.nml:1:', 'motion(1) = ''prescribed''', &
                       'u(1) = -1.0', 'side wall at x = 0', 't = 0.9 s', 'run ends at t = 1.0'])
    call expect_error('error: a prescribed path into a fixed particle', &
                      '&particles count = 2, motion = ''prescribed'', ''fixed'','// &
                      ' y = 4, 2, v = -2 /', &
                      [character(len=40) :: 'input/test.nml:1:', 'runs into particle 2', &
                       '''fixed''', 't = 0.9 s'])
    call config_check_text('', FILE, err)
    call expect_parts('error: an empty scene file', err, &
                      [character(len=40) :: FILE//': is empty', '&domain', '--print-defaults'])
    call config_check_text('! a comment'//new_line('a')//'   '//new_line('a'), FILE, err)
    call expect_parts('error: a scene file of comments only', err, &
                      [character(len=40) :: FILE//': holds only comments', '&lbm'])
    call config_check_text('! a comment'//new_line('a')//'&lbm /', FILE, err)
    call check('a file with a group passes the text check', len(err) == 0)
  end subroutine test_derived_and_text_errors

  subroutine test_particle_errors()
    character(len=*), parameter :: TWO = '&particles count = 2, x = 1, 1, y = 2, 3 '
    call expect_error('error: count above MAX_PARTICLES', '&particles count = 1000001 /', &
                      [character(len=40) :: 'input/test.nml:1:', '&particles', 'count', &
                       '= 1000001', '0 <= count <= 1000000'])
    call expect_error('error: negative count', '&particles count = -1 /', &
                      [character(len=40) :: '&particles', 'count = -1', '0 <= count <= 1000000'])
    call expect_error('error: index past MAX_PARTICLES', '&particles x(1000001) = 1 /', &
                      [character(len=40) :: '&particles', 'x(1000001)', 'index 1000001'])
    call expect_error('error: diameter 0', TWO//'diameter(2) = 0 /', &
                      [character(len=40) :: 'input/test.nml:1:', '&particles diameter(2) = 0.0', &
                       'out of range', 'diameter(i) > 0'])
    call expect_error('error: negative density', '&particles density(1) = -1 /', &
                      [character(len=40) :: '&particles density(1) = -1.0', 'density(i) > 0'])
    call expect_error('error: motion not a choice', TWO//'motion(2) = ''fixd'' /', &
                      [character(len=40) :: 'input/test.nml:1:', &
                       '&particles motion(2) = ''fixd''', '''free'', ''fixed'', ''prescribed''', &
                       'did you mean ''fixed'''])
    call expect_error('error: motion in a list not a choice', &
                      '&particles motion = free, moving /', &
                      [character(len=40) :: '&particles motion(2) = ''moving''', 'not one of'])
    call expect_error('error: too many motions', &
                      '&particles count = 16, motion(16) = free, fixed /', &
                      [character(len=40) :: '&particles', 'motion(16)', 'too many'])
    call expect_error('error: motion value too long', &
                      '&particles motion(1) = ''prescribed_motion'' /', &
                      [character(len=40) :: '&particles motion(1)', 'too long', 'at most 16'])
    call expect_error('error: negative gravity', '&particles gravity = -980 /', &
                      [character(len=40) :: '&particles gravity = -980.0', 'gravity >= 0'])
    call expect_error('error: bounce_back not a choice', '&coupling bounce_back = ''ladd'' /', &
                      [character(len=40) :: '&coupling bounce_back = ''ladd''', &
                       '''halfway'', ''yu'', ''bfl'''])
    call expect_error('error: momentum not a choice', '&coupling momentum = ''wen'' /', &
                      [character(len=40) :: '&coupling momentum = ''wen''', &
                       '''paper'', ''galilean'''])
    call expect_error('error: stiffness 0', '&collision stiffness = 0 /', &
                      [character(len=40) :: '&collision stiffness = 0.0', 'stiffness > 0'])
    call expect_error('error: negative stiffness_overlap', &
                      '&collision stiffness_overlap = -1e-7 /', &
                      [character(len=40) :: '&collision stiffness_overlap = -1.0e-7', &
                       'stiffness_overlap > 0'])
    call expect_error('error: negative range', '&collision range = -0.5 /', &
                      [character(len=40) :: '&collision range = -0.5', 'range >= 0'])
    call expect_error('error: substeps 0', '&collision substeps = 0 /', &
                      [character(len=40) :: '&collision substeps = 0', '1 <= substeps <= 1000'])
    call expect_error('error: substeps 1001', '&collision substeps = 1001 /', &
                      [character(len=40) :: '&collision substeps = 1001', '1 <= substeps <= 1000'])

    ! Fixed particles do not move.
    call expect_error('error: fixed particle with u', TWO//'motion(2) = ''fixed'', u(2) = 1 /', &
                      [character(len=40) :: 'input/test.nml:1:', 'motion(2) = ''fixed''', &
                       '&particles u(2) = 1.0', 'omega(2) = 0', 'prescribed'])
    call expect_error('error: fixed particle with omega', &
                      TWO//'motion = fixed, fixed, omega(1) = -3 /', &
                      [character(len=40) :: 'motion(1) = ''fixed''', '&particles omega(1) = -3.0'])

    ! In the channel, clear of the walls (dx = 0.004 cm, width 2 cm, height 5 cm).
    call expect_error('error: particle overlaps the side wall x = 0', &
                      TWO//'x(2) = 0.05 /', &
                      [character(len=40) :: 'input/test.nml:1:', '&particles x(2) = 0.05', &
                       'diameter(2) = 0.2', 'wall at x = 0', 'allowed: 0.1 < x(2) < 1.9'])
    call expect_error('error: particle touching the side wall is an overlap', &
                      TWO//'x(1) = 0.1 /', &
                      [character(len=40) :: '&particles x(1) = 0.1', 'wall at x = 0', &
                       'touching counts as overlap', '0.1 < x(1) < 1.9'])
    call expect_error('error: particle overlaps the side wall x = width', &
                      TWO//'x(1) = 1.95 /', &
                      [character(len=40) :: '&particles x(1) = 1.95', 'wall at x = 2.0', &
                       '&domain width = 2.0', '0.1 < x(1) < 1.9'])
    call expect_error('error: centre outside the channel', TWO//'x(1) = -0.5 /', &
                      [character(len=40) :: '&particles x(1) = -0.5', 'outside the channel'])
    call expect_error('error: particles in a channel with periodic sides', &
                      '&domain sides = ''periodic'' / '//TWO//'x(2) = 0.5 /', &
                      [character(len=40) :: '&particles count = 2', 'sides = ''periodic''', &
                       'walls or open ends'])
    call expect_error('error: particles in a channel with periodic ends', &
                      '&domain lower = ''periodic'', upper = ''periodic'' / '//TWO//'/', &
                      [character(len=40) :: '&particles count = 2', 'lower = ''periodic''', &
                       'walls or open ends'])
    call expect_error('error: particle overlaps the lower wall end', TWO//'y(1) = 0.05 /', &
                      [character(len=40) :: '&particles y(1) = 0.05', 'wall at y = 0', &
                       'lower = ''wall''', '0.1 < y(1) < 4.9'])
    call expect_error('error: particle overlaps the upper wall end', TWO//'y(2) = 4.95 /', &
                      [character(len=40) :: '&particles y(2) = 4.95', 'wall at y = 5.0', &
                       '0.1 < y(2) < 4.9'])
    call expect_error('error: centre beyond an open end', &
                      '&domain upper = ''outflow'' / '//TWO//'y(2) = 5.5 /', &
                      [character(len=40) :: '&particles y(2) = 5.5', 'outside the channel', &
                       'upper = ''outflow''', '0.1 < y(2) <= 5.0'])
    call expect_error('error: particle as wide as the channel', &
                      '&domain width = 0.2 / &particles count = 1, x = 0.1 /', &
                      [character(len=40) :: '&particles x(1) = 0.1', 'diameter(1) = 0.2', &
                       'not narrower', 'diameter(1) < width'])
    call expect_error('error: a position set by --set names the option', TWO//'/', &
                      [character(len=40) :: '--set particles.x(2)=0.05', 'x(2) = 0.05'], &
                      [character(len=40) :: 'particles.x(2)=0.05'])

    ! No overlap between particles (contact distance = sum of the radii).
    call expect_error('error: two particles overlap', &
                      '&particles count = 2, x = 1, 1, y = 4.0, 3.9 /', &
                      [character(len=40) :: 'input/test.nml:1:', '&particles', &
                       'particles 1 and 2 overlap', 'y(1) = 4.0', 'y(2) = 3.9', &
                       'distance of the centres 0.1', 'contact distance', '= 0.2 cm'])
    call expect_error('error: the third particle overlaps the first', &
                      '&particles count = 3, x = 1.0, 1.0, 1.1, y = 4.0, 3.0, 4.05,'// &
                      ' diameter = 0.2, 0.2, 0.1 /', &
                      [character(len=40) :: 'particles 1 and 3 overlap', 'x(3) = 1.1', &
                       'diameter(3) = 0.1', '= 0.15'])

    ! Resolution: at least 4 cells per diameter.
    call expect_error('error: fewer than 4 cells per diameter', TWO//'diameter(2) = 0.012 /', &
                      [character(len=40) :: 'input/test.nml:1:', '&particles diameter(2) = 0.012', &
                       '&lbm dx = 0.004', '3.0 cells per diameter', 'diameter(2)/dx >= 4', &
                       'dx <= diameter(2)/4 = 0.003 cm'])
    call expect_error('error: dx set by --set too coarse for a particle', TWO//'/', &
                      [character(len=40) :: '--set lbm.dx=0.1', '&lbm dx = 0.1', &
                       'diameter(1) = 0.2', '2.0 cells per diameter', '0.05 cm'], &
                      [character(len=40) :: 'lbm.dx=0.1'])
  end subroutine test_particle_errors

  ! ---------------------------------------------------------------- namelist forms
  ! Every form of Fortran namelist input the reader accepts (repeat counts, null values,
  ! sections and strides, &end/$end, strings over lines, logical and real forms), and a precise
  ! message for every mistake in them. Bugs caught: a standard form refused or misread, a value
  ! put into the wrong element, a mistake accepted silently or reported without its place, key
  ! or value. Expected values follow from the texts written here and the standard's rules.

  subroutine test_nml_repeat_counts()
    type(config_t) :: cfg
    call load_ok('r*c in a real array', P16//'&particles diameter = 3*0.25, 0.5 /', cfg)
    call check('3*0.25 fills elements 1-3, the next value element 4, the rest keep 0.2', &
               all(same(cfg%particles%diameter(1:5), [0.25_wp, 0.25_wp, 0.25_wp, 0.5_wp, 0.2_wp])))
    call load_ok('r*c filling a whole array', '&particles x = 16*0.75 /', cfg)
    call check('16*0.75 fills all 16 elements', all(same(cfg%particles%x, 0.75_wp)))
    call load_ok('1*c on a scalar', '&lbm tau = 1*0.9 /', cfg)
    call check('1*0.9 sets a scalar', same(cfg%lbm%tau, 0.9_wp))
    call load_ok('r*''text'' and r*text in an array of choices', &
                 P16//'&particles motion = 2*''fixed'', 2*Prescribed /', cfg)
    call check('2*''fixed'', 2*prescribed fill elements 1-4', &
               all(cfg%particles%motion(1:5) == [character(len=16) :: 'fixed', 'fixed', &
                                                 'prescribed', 'prescribed', 'free']))
    call load_ok('r*"text" with a doubled quote', '&output dir = 1*"a""b" /', cfg)
    call check('1*"a""b" is a"b', cfg%output%dir == 'a"b')
    call load_ok('r* on an integer and a logical', &
                 '&run steps = 1*12 / &output overwrite = 1*T /', cfg)
    call check('1*12 and 1*T', cfg%run%steps == 12 .and. cfg%output%overwrite)
  end subroutine test_nml_repeat_counts

  subroutine test_nml_null_values()
    type(config_t) :: cfg
    character(len=*), parameter :: BASE = '&particles omega = 16*9 /'//NL
    call load_ok('r* null values', BASE//'&particles omega = 1, 2*, 4 /', cfg)
    call check('1, 2*, 4: elements 2 and 3 keep their value', &
               all(same(cfg%particles%omega(1:5), [1.0_wp, 9.0_wp, 9.0_wp, 4.0_wp, 9.0_wp])))
    call load_ok('empty items between commas', BASE//'&particles omega = 1,, 3 , ,5 /', cfg)
    call check('1,, 3 , ,5: elements 2 and 4 keep their value', &
               all(same(cfg%particles%omega(1:6), [1.0_wp, 9.0_wp, 3.0_wp, 9.0_wp, 5.0_wp, &
                                                   9.0_wp])))
    call load_ok('a comma right after =', BASE//'&particles omega = , 2 /', cfg)
    call check('= , 2: element 1 keeps its value', &
               all(same(cfg%particles%omega(1:3), [9.0_wp, 2.0_wp, 9.0_wp])))
    call load_ok('a null scalar', '&lbm tau = , dx = 0.002 / &run steps = / '// &
                 '&output dir = 1* /', cfg)
    call check('tau = , and steps = / leave the defaults', same(cfg%lbm%tau, 0.65_wp) .and. &
               same(cfg%lbm%dx, 0.002_wp) .and. cfg%run%steps == 0 .and. cfg%output%dir == '')
    call load_ok('a comma before / or before the next key is no null value', &
                 '&lbm tau = 0.7, / &fluid body_force = 1, 2, density = 1.5, /', cfg)
    call check('tau = 0.7, / sets tau; a list ends at the next key', &
               same(cfg%lbm%tau, 0.7_wp) .and. same(cfg%fluid%density, 1.5_wp) .and. &
               all(same(cfg%fluid%body_force, [1.0_wp, 2.0_wp])))
    call load_ok('a null in a list of choices over lines', &
                 '&particles motion = ''fixed'','//NL//'  , ''prescribed'' /', cfg)
    call check('''fixed'', <newline> , ''prescribed'': one null between the commas', &
               all(cfg%particles%motion(1:3) == [character(len=16) :: 'fixed', 'free', &
                                                 'prescribed']))
  end subroutine test_nml_null_values

  subroutine test_nml_sections()
    type(config_t) :: cfg
    real(wp) :: e(16)
    integer :: j
    e = [(real(j, wp), j=1, 16)]
    call load_ok('a:b', P16//'&particles diameter(1:2) = 0.2, 0.1 /', cfg)
    call check('diameter(1:2) = 0.2, 0.1', all(same(cfg%particles%diameter(1:3), &
                                                    [0.2_wp, 0.1_wp, 0.2_wp])))
    call load_ok('a:b:s', '&particles x(2:9:3) = 7, 8, 9 /', cfg)
    call check('x(2:9:3) sets elements 2, 5, 8 only', &
               same(cfg%particles%x(2), 7.0_wp) .and. same(cfg%particles%x(5), 8.0_wp) .and. &
               same(cfg%particles%x(8), 9.0_wp) .and. &
               count(.not. same(cfg%particles%x, 1.0_wp)) == 3)
    call load_ok('a negative stride', '&particles y(16:1:-5) = 5, 6, 7, 8 /', cfg)
    call check('y(16:1:-5) sets 16, 11, 6, 1 in that order', &
               all(same(cfg%particles%y([16, 11, 6, 1]), [5.0_wp, 6.0_wp, 7.0_wp, 8.0_wp])) &
               .and. count(.not. same(cfg%particles%y, 1.0_wp)) == 4)
    call load_ok('a:, :b, : and ::s', '&particles u(15:) = 2*5 v(:2) = 6, 7 '// &
                 'omega(:) = 16*3 density(::8) = 2*4 /', cfg)
    call check('u(15:) is 15-16, v(:2) is 1-2, omega(:) all, density(::8) is 1 and 9', &
               all(same(cfg%particles%u(14:16), [0.0_wp, 5.0_wp, 5.0_wp])) .and. &
               all(same(cfg%particles%v(1:3), [6.0_wp, 7.0_wp, 0.0_wp])) .and. &
               all(same(cfg%particles%omega, 3.0_wp)) .and. &
               count(same(cfg%particles%density, 4.0_wp)) == 2 .and. &
               same(cfg%particles%density(9), 4.0_wp))
    call load_ok('an upper bound beyond the array, every element inside', &
                 '&particles x(2:18:7) = 3*2 /', cfg)
    call check('x(2:18:7) sets 2, 9 and 16', all(same(cfg%particles%x([2, 9, 16]), 2.0_wp)) &
               .and. count(same(cfg%particles%x, 2.0_wp)) == 3)
    call load_ok('a single element', '&particles diameter(16) = 0.5 /', cfg)
    call check('diameter(16) only', same(cfg%particles%diameter(16), 0.5_wp) .and. &
               all(same(cfg%particles%diameter(1:15), 0.2_wp)))
    call load_ok('an element with a list', P16//'&particles u(4) = 1, 2, 3 /', cfg)
    call check('u(4) = 1, 2, 3 fills elements 4-6', &
               all(same(cfg%particles%u(3:7), [0.0_wp, 1.0_wp, 2.0_wp, 3.0_wp, 0.0_wp])))
    call load_ok('a list from the first element, fewer values than elements', &
                 P16//'&particles x = 1, 2, 3 /', cfg)
    call check('x = 1, 2, 3 fills 1-3, the rest keep 1.0', &
               all(same(cfg%particles%x(1:4), [1.0_wp, 2.0_wp, 3.0_wp, 1.0_wp])))
    call load_ok('a list of all 16 values over three lines', '&particles omega = 1, 2, 3, 4,'// &
                 NL//' 5 6 7 8 9 10'//NL//' 11, 12, 13, 14, 15, 16 /', cfg)
    call check('16 values over lines', all(same(cfg%particles%omega, e)))
    call load_ok('blanks around an index (an extension)', &
                 P16//'&particles x ( 2 : 3 ) = 5 6, y (2) = 7 /', cfg)
    call check('x ( 2 : 3 ) and y (2)', all(same(cfg%particles%x(1:4), [1.0_wp, 5.0_wp, &
                                                                        6.0_wp, 1.0_wp])) &
               .and. same(cfg%particles%y(2), 7.0_wp))
    call load_ok('a section in capitals, a signed index', &
                 P16//'&PARTICLES DIAMETER(+2:+3) = 2*0.3 /', cfg)
    call check('DIAMETER(+2:+3)', all(same(cfg%particles%diameter(1:4), [0.2_wp, 0.3_wp, &
                                                                         0.3_wp, 0.2_wp])))
  end subroutine test_nml_sections

  subroutine test_nml_group_forms()
    type(config_t) :: cfg
    call load_ok('&end, $group $end, $group /, &group $end', &
                 '&lbm tau = 0.7 &end'//NL//'$fluid density = 1.5 $end'//NL// &
                 '$RUN steps = 3 /'//NL//'&output overwrite = T $END', cfg)
    call check('every terminator closes its group', same(cfg%lbm%tau, 0.7_wp) .and. &
               same(cfg%fluid%density, 1.5_wp) .and. cfg%run%steps == 3 .and. &
               cfg%output%overwrite)
    call load_ok('mixed case of group and key names', &
                 '&Fluid Density = 1.25, VISCOSITY = 0.02, Body_Force(2) = -1 /', cfg)
    call check('names in any case', same(cfg%fluid%density, 1.25_wp) .and. &
               same(cfg%fluid%viscosity, 0.02_wp) .and. same(cfg%fluid%body_force(2), -1.0_wp))
    call load_ok('comments and a value on the next line', '! head'//NL//'&lbm ! a group'//NL// &
                 '  tau = ! the value follows'//NL//'    0.8'//NL//' / ! closed', cfg)
    call check('tau = <newline> 0.8', same(cfg%lbm%tau, 0.8_wp))
    call load_ok('no blanks at all', '&lbm tau=0.7,dx=0.002/&run steps=4/', cfg)
    call check('tau=0.7,dx=0.002/', same(cfg%lbm%tau, 0.7_wp) .and. same(cfg%lbm%dx, 0.002_wp) &
               .and. cfg%run%steps == 4)
    call load_ok('items on one line separated by blanks only', &
                 '&particles count = 0 x = 2 y = 3 /', cfg)
    call check('x = 2 y = 3', same(cfg%particles%x(1), 2.0_wp) .and. &
               same(cfg%particles%y(1), 3.0_wp))
  end subroutine test_nml_group_forms

  subroutine test_nml_strings()
    type(config_t) :: cfg
    character(len=*), parameter :: CR = achar(13)
    call load_ok('a string continued on the next line', '&output dir = ''runs/'//NL// &
                 'case'' /', cfg)
    call check('''runs/ <newline> case'' is runs/case', cfg%output%dir == 'runs/case')
    call load_ok('a string continued after a CR LF line end', '&output dir = "a'//CR//NL// &
                 'b" /', cfg)
    call check('"a <CR LF> b" is ab', cfg%output%dir == 'ab')
    call load_ok('both quotes, doubled quotes, separators inside', &
                 '&output dir = ''it''''s, a "b" / c! d'' /', cfg)
    call check('the whole text between the quotes', cfg%output%dir == 'it''s, a "b" / c! d')
    call load_ok('an unquoted choice (an extension)', '&lbm collision = bgk /', cfg)
    call check('collision = bgk', cfg%lbm%collision == 'bgk')
  end subroutine test_nml_strings

  subroutine test_nml_logicals()
    type(config_t) :: cfg
    character(len=12) :: yes(6), no(5)
    integer :: j
    yes = [character(len=12) :: '.true.', '.T.', 't', 'true', '.t', '.Tuesday.']
    no = [character(len=12) :: '.false.', '.F.', 'f', 'False', '.f']
    do j = 1, size(yes)
      call load_ok('logical '//trim(yes(j)), '&output overwrite = '//trim(yes(j))//' /', cfg)
      call check('logical '//trim(yes(j))//' is true', cfg%output%overwrite)
    end do
    do j = 1, size(no)
      call load_ok('logical '//trim(no(j)), '&output overwrite = T, overwrite = '// &
                   trim(no(j))//' /', cfg)
      call check('logical '//trim(no(j))//' is false',.not. cfg%output%overwrite)
    end do
  end subroutine test_nml_logicals

  subroutine test_nml_reals()
    type(config_t) :: cfg
    call load_ok('real forms', '&particles x = 1.0+3, 2.5-1, -0.0, 5., 1E0, 2d-1, +7 /', cfg)
    call check('1.0+3 = 1000, 2.5-1 = 0.25, -0.0 keeps its sign, 5., 1E0, 2d-1, +7', &
               all(same(cfg%particles%x(1:7), [1000.0_wp, 0.25_wp, -0.0_wp, 5.0_wp, 1.0_wp, &
                                               0.2_wp, 7.0_wp])))
  end subroutine test_nml_reals

  subroutine test_nml_overrides()
    type(config_t) :: cfg
    call load_ok('--set with a repeat count and a section', '', cfg, &
                 [character(len=48) :: 'particles.diameter=3*0.1', 'particles.x(2:6:2)=4,5,6', &
                  'particles.motion=2*fixed,1*,2*''prescribed''', 'particles.motion(3)=free'])
    call check('--set particles.diameter=3*0.1', &
               all(same(cfg%particles%diameter(1:4), [0.1_wp, 0.1_wp, 0.1_wp, 0.2_wp])))
    call check('--set particles.motion=2*fixed,1*,2*''prescribed'' (then motion(3)=free)', &
               all(cfg%particles%motion(1:6) == [character(len=16) :: 'fixed', 'fixed', 'free', &
                                                 'prescribed', 'prescribed', 'free']))
    call check('--set particles.x(2:6:2)=4,5,6', &
               all(same(cfg%particles%x(1:6), [1.0_wp, 4.0_wp, 1.0_wp, 5.0_wp, 1.0_wp, 6.0_wp])))
  end subroutine test_nml_overrides

  subroutine test_nml_errors()
    character(len=*), parameter :: L3 = '&particles'//NL//'  count = 16,'//NL//'  '
    call expect_error('error: repeat count 0', L3//'diameter = 0*0.1 /', &
                      [character(len=60) :: 'input/test.nml:3:', '&particles', 'diameter', &
                       '0*0.1', 'repeat count 0', 'not positive'])
    call expect_error('error: negative repeat count of a string', &
                      '&particles motion = -1*''free'' /', &
                      [character(len=60) :: 'input/test.nml:1:', '&particles', 'motion', &
                       '-1*''free''', 'not positive'])
    call expect_error('error: repeat count not a whole number', '&particles x = 2.5*1 /', &
                      [character(len=60) :: 'input/test.nml:1:', '&particles', 'x', '2.5*1', &
                       'repeat count ''2.5''', 'not a whole number'])
    call expect_error('error: repeat counts beyond the array', L3//'diameter = 15*0.1, 2*0.2 /', &
                      [character(len=60) :: 'input/test.nml:3:', '&particles', 'diameter', &
                       '15*0.1, 2*0.2', 'too many values (17, counting repeats)', &
                       'diameter takes 16 values'])
    call expect_error('error: null values count too', '&fluid body_force = 3* /', &
                      [character(len=60) :: 'input/test.nml:1:', '&fluid', 'body_force', &
                       '3*', 'too many values (3', 'body_force takes 2 values'])
    call expect_error('error: more values than a section holds', L3//'x(1:2) = 1, 2, 3 /', &
                      [character(len=60) :: 'input/test.nml:3:', '&particles', 'x(1:2)', &
                       '1, 2, 3', 'too many values (3)', 'the section x(1:2) takes 2 values'])
    call expect_error('error: more values than follow an element', &
                      '&particles count = 16, x(15) = 1 2 3 /', &
                      [character(len=60) :: 'input/test.nml:1:', '&particles', 'x(15)', &
                       '1, 2, 3', 'too many values', 'from x(15) on, x takes 2 values'])
    call expect_error('error: a zero stride', L3//'x(1:4:0) = 1 /', &
                      [character(len=60) :: 'input/test.nml:3:', '&particles', 'x(1:4:0)', &
                       '= 1', 'stride', 'is 0'])
    call expect_error('error: a section without elements', '&particles x(3:2) = 1 /', &
                      [character(len=60) :: 'input/test.nml:1:', '&particles', 'x(3:2)', &
                       '= 1', 'selects no element'])
    call expect_error('error: a section starting outside', '&particles count = 16, x(0:2) = 1 /', &
                      [character(len=60) :: 'input/test.nml:1:', '&particles', 'x(0:2)', &
                       'element 0', 'out of range', 'x has 16 elements, x(1) to x(16)'])
    call expect_error('error: a section ending outside', &
                      '&particles count = 16, y(20:1:-1) = 1 /', &
                      [character(len=60) :: 'input/test.nml:1:', '&particles', 'y(20:1:-1)', &
                       'element 20', 'y(1) to y(16)'])
    call expect_error('error: an element outside', L3//'omega(17) = 1 /', &
                      [character(len=60) :: 'input/test.nml:3:', '&particles', 'omega(17)', &
                       'index 17', 'out of range', 'omega(1) to omega(16)'])
    call expect_error('error: an index that is not a whole number', '&particles x(1.5) = 1 /', &
                      [character(len=60) :: 'input/test.nml:1:', '&particles', 'x(1.5)', &
                       '= 1', 'not a whole number'])
    call expect_error('error: a bound that is not a whole number', '&particles x(1:b) = 1 /', &
                      [character(len=60) :: 'input/test.nml:1:', 'x(1:b)', 'upper bound ''b''', &
                       'not a whole number'])
    call expect_error('error: two subscripts', '&particles x(1,2) = 1 /', &
                      [character(len=60) :: 'input/test.nml:1:', '&particles', 'x(1,2)', &
                       'one dimension'])
    call expect_error('error: three colons', '&particles x(1:2:3:4) = 1 /', &
                      [character(len=60) :: 'input/test.nml:1:', 'x(1:2:3:4)', 'not an index'])
    call expect_error('error: an index not closed', L3//'x(1:2 = 1 /', &
                      [character(len=60) :: 'input/test.nml:3:', '(1:2', 'no closing '')'''])
    call expect_error('error: a section of a scalar', '&lbm tau(1:2) = 0.7 /', &
                      [character(len=60) :: 'input/test.nml:1:', '&lbm', 'tau(1:2)', '0.7', &
                       'not an array'])
    call expect_error('error: a string never closed names the line it starts on', &
                      '&output'//NL//'dir = ''abc'//NL//'def /'//NL, &
                      [character(len=60) :: 'input/test.nml:2:', 'abc', 'not closed'])
    call expect_error('error: a missing quote points to the string that ran on', &
                      '&output dir = ''abc'//NL//'/'//NL//'&lbm collision = ''bgk'' /', &
                      [character(len=60) :: 'input/test.nml:3:', 'not closed', &
                       'starts on line 1 runs over several lines'])
    call expect_error('error: an integer too large', '&run steps = 12345678901 /', &
                      [character(len=60) :: 'input/test.nml:1:', '&run', 'steps', &
                       '12345678901', 'too large for an integer'])
    call expect_error('error: an infinite real', '&lbm tau = -Inf /', &
                      [character(len=60) :: 'input/test.nml:1:', '&lbm', 'tau', '-Inf', &
                       'not a finite real number'])
    call expect_error('error: a real beyond the largest double', '&lbm tau = 1e400 /', &
                      [character(len=60) :: 'input/test.nml:1:', '&lbm', 'tau', '1e400', &
                       'not a finite real number'])
    call expect_error('error: a logical neither T nor F', '&output overwrite = .x. /', &
                      [character(len=60) :: 'input/test.nml:1:', '&output', 'overwrite', '.x.', &
                       'not a logical'])
    call expect_error('error: a quoted logical', '&output overwrite = ''T'' /', &
                      [character(len=60) :: '&output', 'overwrite', '''T''', 'not a logical'])
    call expect_error('error: a repeated value of the wrong type names its element', &
                      '&particles motion = 2*''fixed'' / &particles x(3) = 2*abc /', &
                      [character(len=60) :: 'input/test.nml:1:', '&particles', 'x(3) = abc', &
                       'not a real number'])
    call expect_error('error: $ without a group name', '$ tau = 1 /', &
                      [character(len=60) :: 'input/test.nml:1:', '''$'' without a group name'])
  end subroutine test_nml_errors

  !> Input the reader once got wrong: each message must name group, key and value (and the
  !! --set option a value came from), a byte-order mark is no key, an overflowing literal is
  !! refused (the debug build traps overflow: there a trapped read kills this test).
  subroutine test_input_defects()
    type(config_t) :: cfg
    character(len=:), allocatable :: err
    character(len=*), parameter :: CHANNEL = '&domain width = 1.0, height = 0.3 /'//NL// &
                                   '&lbm dx = 0.05 /'
    ! an unclosed '(' once named neither &particles nor x
    call expect_error('error: an index without its '')''', '&particles'//NL//'  x(1 = 1.0 /', &
                      [character(len=60) :: 'input/test.nml:2:', '&particles', 'x(1 = 1.0', &
                       'no closing '')''', 'x(i), x(a:b) or x(a:b:s)'])
    ! an unclosed string once named neither &domain nor sides
    call expect_error('error: a string without its closing quote', &
                      '&domain'//NL//'  sides = ''wall'//NL//'/', &
                      [character(len=60) :: 'input/test.nml:2:', '&domain', 'sides = ''wall', &
                       'not closed'])
    ! 99999999999 is a whole number: once called 'not a whole number'
    call expect_error('error: an index beyond the integer range', &
                      '&particles count = 16, x(99999999999) = 1 /', &
                      [character(len=60) :: 'input/test.nml:1:', '&particles', &
                       'x(99999999999)', 'out of range', 'x(1) to x(16)'])
    call expect_error('error: a section bound beyond the integer range', &
                      '&particles count = 16, x(1:99999999999) = 1 /', &
                      [character(len=60) :: 'input/test.nml:1:', '&particles', &
                       'x(1:99999999999)', 'upper bound', 'out of range', 'x(1) to x(16)'])
    call expect_error('error: a real beyond the double range', '&domain width = 1e999 /', &
                      [character(len=60) :: 'input/test.nml:1:', '&domain', 'width = 1e999', &
                       'not a finite real number', 'width > 0'])
    ! a byte-order mark was once refused as "'<3 bytes>' is outside a group"
    call load_ok('a leading byte-order mark', char(239)//char(187)//char(191)// &
                 '&lbm tau = 0.7 /', cfg)
    call check('a leading byte-order mark: tau is read', same(cfg%lbm%tau, 0.7_wp))
    ! width from --set, dx from line 2: the message once cited line 2 for width = 0.1
    call config_load(cfg, CHANNEL, FILE, [character(len=20) :: 'domain.width=0.1'], err)
    call expect_parts('error: a joint rule names the --set option of its value', err, &
                      [character(len=60) :: 'input/test.nml: --set domain.width=0.1', &
                       '&domain width = 0.1', 'dx = 0.05', 'nx >= 3'])
    call check('error: a joint rule does not cite a file line for a --set value', &
               index(err, 'test.nml:2') == 0)
    call expect_error('error: a joint rule of file values names the line', &
                      '&domain width = 0.1, height = 0.3 /'//NL//'&lbm dx = 0.05 /', &
                      [character(len=60) :: 'input/test.nml:2:', '&domain width = 0.1', 'nx >= 3'])
    ! non-printing bytes are shown by their codes; UTF-8 characters as they are
    call check('printable: ESC, NUL, DEL as codes', &
               printable('tau = 1.0'//achar(27)//achar(0)//achar(127)) == &
               'tau = 1.0<1b><00><7f>')
    call check('printable: a stray Latin-1 byte as its code', &
               printable('ta'//char(233)//' = 1') == 'ta<e9> = 1')
    call check('printable: a UTF-8 character kept', &
               printable('mu = 1 '//char(194)//char(181)//'m') == &
               'mu = 1 '//char(194)//char(181)//'m')
  end subroutine test_input_defects

  !> Each choice reaches the program as its named constant: config_load sets the constant of
  !! every choice from its text (defaults, file, any case), and every value the input allows
  !! for a choice key has a constant of its own, so no allowed value can reach a `select case`
  !! as an unknown code.
  subroutine test_choice_codes()
    type(config_t) :: cfg
    type(config_t), target :: c
    type(registry_t) :: reg
    integer :: j, a, b, n
    integer, allocatable :: codes(:)
    logical :: ok, good
    call load_ok('defaults as constants', '', cfg)
    call check('default choices as constants', &
               all([cfg%domain%sides_kind, cfg%domain%lower_kind, cfg%domain%upper_kind] == &
                   END_WALL) .and. &
               cfg%lbm%collision_kind == COLLISION_MRT .and. &
               cfg%lbm%streaming_kind == STREAMING_IN_PLACE .and. &
               cfg%lbm%precision_kind == PRECISION_DOUBLE .and. &
               cfg%inlet%profile_kind == PROFILE_PARABOLIC .and. &
               cfg%initial%flow_kind == FLOW_REST .and. cfg%coupling%bounce_back_kind == BB_YU &
               .and. cfg%coupling%momentum_kind == MOMENTUM_PAPER .and. &
               cfg%coupling%interior_kind == INTERIOR_SOLID)
    call load_ok('choices in any case', '&lbm collision = "BGK", streaming = "two_lattice", '// &
                 'precision = "single" / &coupling bounce_back = "Bfl", momentum = '// &
                 '"galilean", interior = "fluid" /', cfg)
    call check('choices of the file as constants', cfg%lbm%collision_kind == COLLISION_BGK &
               .and. cfg%lbm%streaming_kind == STREAMING_TWO_LATTICE .and. &
               cfg%lbm%precision_kind == PRECISION_SINGLE .and. &
               cfg%coupling%bounce_back_kind == BB_BFL .and. &
               cfg%coupling%momentum_kind == MOMENTUM_GALILEAN .and. &
               cfg%coupling%interior_kind == INTERIOR_FLUID)
    call load_ok('open ends', '&domain lower = "velocity", upper = "outflow" / '// &
                 '&inlet velocity = 0.1, profile = "uniform" /', cfg)
    call check('ends and profile as constants', cfg%domain%lower_kind == END_VELOCITY .and. &
               cfg%domain%upper_kind == END_OUTFLOW .and. &
               cfg%inlet%profile_kind == PROFILE_UNIFORM)
    call load_ok('periodic Taylor-Green', '&domain sides = "periodic", lower = "periodic", '// &
                 'upper = "periodic" / &initial flow = "taylor_green", velocity = 0.1 /', cfg)
    call check('periodic and taylor_green as constants', &
               all([cfg%domain%sides_kind, cfg%domain%lower_kind, cfg%domain%upper_kind] == &
                   END_PERIODIC) .and. &
               cfg%initial%flow_kind == FLOW_TAYLOR_GREEN)
    call load_ok('a prescribed particle', '&particles count = 2, x = 0.5, 1.5, y = 2.5, 2.5, '// &
                 'motion(2) = "prescribed" /', cfg)
    call check('motion per particle as constants', size(cfg%particles%motion_kind) == 2 .and. &
               all(cfg%particles%motion_kind == [MOTION_FREE, MOTION_PRESCRIBED]))
    ! every allowed value of every choice key, set in turn: a constant > 0, one per value
    ok = .true.
    n = 0
    call config_registry(c, reg)
    do j = 1, size(reg%keys)
      associate (k => reg%keys(j))
        ! pair.upper is turned into particle positions by the input itself
        if (k%kind /= KEY_CHOICE .or. (k%group == 'pair' .and. k%name == 'upper')) cycle
        allocate (codes(0))
        a = 1
        do while (a <= len(k%choices))
          b = index(k%choices(a:)//' ', ' ') + a - 1
          if (k%n > 0) then
            k%sa(1)%s = k%choices(a:b - 1)
          else
            k%s = k%choices(a:b - 1)
          end if
          call config_choices(c)
          codes = [codes, choice_kind_of(c, k%group//'.'//k%name)]
          a = b + 1
        end do
        good = all(codes > 0)
        do a = 1, size(codes)
          if (count(codes == codes(a)) /= 1) good = .false.
        end do
        if (.not. good) write (*, '(a)') '  no constant of its own: '//k%group//'.'//k%name
        ok = ok .and. good
        n = n + 1
        deallocate (codes)
      end associate
    end do
    call check('every allowed choice has a constant of its own (13 keys)', ok .and. n == 13)
  end subroutine test_choice_codes

  !> The constant config_choices set for the choice key `key` of `c` (its first element for
  !! particles.motion).
  integer function choice_kind_of(c, key) result(code)
    type(config_t), intent(in) :: c
    character(len=*), intent(in) :: key
    select case (key)
    case ('domain.sides'); code = c%domain%sides_kind
    case ('domain.lower'); code = c%domain%lower_kind
    case ('domain.upper'); code = c%domain%upper_kind
    case ('lbm.collision'); code = c%lbm%collision_kind
    case ('lbm.streaming'); code = c%lbm%streaming_kind
    case ('lbm.precision'); code = c%lbm%precision_kind
    case ('inlet.profile'); code = c%inlet%profile_kind
    case ('initial.flow'); code = c%initial%flow_kind
    case ('initial.pressure'); code = c%initial%pressure_kind
    case ('particles.motion'); code = c%particles%motion_kind(1)
    case ('coupling.bounce_back'); code = c%coupling%bounce_back_kind
    case ('coupling.momentum'); code = c%coupling%momentum_kind
    case ('coupling.interior'); code = c%coupling%interior_kind
    case default; code = -1 ! a choice key this test does not know: it fails
    end select
  end function choice_kind_of

end program test_config

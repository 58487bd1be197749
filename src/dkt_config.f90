!> The input of dktlbm, as the rest of the program uses it: load a scene (defaults, the namelist
!> text, the --set overrides, the scene keys expanded, every check, the lattice units), check a
!> configuration built in code, write a configuration back as namelist text, and the output
!> directory. The input layer's parts, re-exported here:
!>
!> - dkt_config_types: one type per namelist group with its defaults, each registering its keys;
!> - dkt_cli: the command line, the help text, reading the scene file;
!> - dkt_config_scene: &pair, &window, cells_per_diameter and mach turned into plain keys, and
!>   the scene's derived quantities (D_1, the window's lower end, the kissing thresholds);
!> - dkt_config_checks, dkt_config_checks_run: the checks, one procedure `chk_<what>` each;
!> - dkt_config_lattice: the conversion to lattice units, which also stores the scene's derived
!>   quantities in lattice_params_t, so that the modules outside the input layer read
!>   components (cfg%output_dir, cfg%given, lp%d1, ...) and take only types from here.
module dkt_config
  use dkt_kinds, only: wp, MAX_PARTICLES
  use dkt_registry, only: registry_t, find_key, check_key, value_text, allowed_text, final_size, &
                          blame
  use dkt_namelist, only: parse_namelist, apply_override
  use dkt_config_types, only: config_t, domain_cfg_t, fluid_cfg_t, lbm_cfg_t, inlet_cfg_t, &
                              initial_cfg_t, particle_cfg_t, particles_cfg_t, pair_cfg_t, &
                              window_cfg_t, diagnostics_cfg_t, coupling_cfg_t, collision_cfg_t, &
                              run_cfg_t, output_cfg_t, config_registry, config_groups, &
                              particles_allocate, config_choices
  use dkt_cli, only: cli_t, parse_command_line, parse_arguments, read_text_file, print_help
  use dkt_config_scene, only: expand
  use dkt_text, only: fmt_num
  use dkt_config_lattice, only: lattice_params_t, particles_lb_t
  use dkt_config_checks_run, only: config_checks
  implicit none
  private
  public :: config_t, domain_cfg_t, fluid_cfg_t, lbm_cfg_t, inlet_cfg_t, initial_cfg_t
  public :: particle_cfg_t, particles_cfg_t, pair_cfg_t, window_cfg_t, diagnostics_cfg_t
  public :: coupling_cfg_t, collision_cfg_t, run_cfg_t, output_cfg_t
  public :: lattice_params_t, particles_lb_t, cli_t, MAX_PARTICLES
  public :: parse_command_line, parse_arguments, read_text_file, config_load, config_validate
  public :: derive_lattice, config_to_namelist, config_output_dir, print_help
  public :: config_check_text, particles_allocate, config_registry, config_choices

  character(len=*), parameter :: NL = new_line('a')

  !> One text of a list of texts of different lengths.
  type :: text_t
    character(len=:), allocatable :: s
  end type text_t

contains

  !> Defaults, then the namelist `text`, then the `overrides` ('group.key=value'), then
  !! validation. `file` names the text in messages and gives cfg%name. On error `err` holds one
  !! message naming file (and line), group, key, value and what is allowed; '' if valid.
  !! `warnings`: what a valid configuration may get wrong (e.g. a coarsely resolved particle),
  !! one message a line, in the same form; '' when there is none or when `err` is set.
  !! `lp`: the lattice parameters of the valid configuration, from the one conversion of the
  !! checks (derive_lattice checks a configuration changed in code).
  !!
  !! One registry, one read of the text and the overrides: the particle arrays grow while they
  !! are read (config_registry with grow) and are then sized as the input asks (particle_slots).
  !! Only an input the read cannot take as it is gets a second read (read_again).
  subroutine config_load(cfg, text, file, overrides, err, warnings, lp)
    type(config_t), intent(out), target :: cfg !! intent(out): every component starts at default
    character(len=*), intent(in) :: text, file
    character(len=*), intent(in) :: overrides(:)
    character(len=:), allocatable, intent(out) :: err
    character(len=:), allocatable, intent(out), optional :: warnings
    type(lattice_params_t), intent(out), optional :: lp
    character(len=:), allocatable :: found
    type(lattice_params_t) :: derived
    type(registry_t), target :: reg
    type(text_t), allocatable :: defaults(:)
    integer :: j, n
    if (present(warnings)) warnings = ''
    cfg%file = file
    cfg%name = basename(file)
    call config_registry(cfg, reg, grow=.true.)
    call value_texts(reg, defaults) ! cfg holds the defaults until the text is read
    call read_input(reg, text, file, overrides, err)
    n = particle_slots(cfg, reg)
    if (len(err) == 0 .and. reg%skipped == 0 .and. reg%reach <= n) then
      call final_size(reg, n)
    else
      call read_again(cfg, reg, n, text, file, overrides, err)
      if (len(err) > 0) return
    end if
    call grown_defaults(reg, defaults)
    do j = 1, size(reg%keys)
      call check_key(reg%keys(j), cfg%file, err)
      if (len(err) > 0) return
    end do
    call namelist_text(reg, defaults, found)
    call move_alloc(found, cfg%given)
    cfg%output_dir = config_output_dir(cfg)
    if (cfg%pair%gamma > 0.0_wp) call pair_owns_particles(cfg, reg, defaults, err)
    if (len(err) > 0) return
    call expand(cfg, reg, err)
    if (len(err) > 0) return
    ! D_2 = pair.d1/pair.gamma is the one value expand derives that its key's range can refuse
    ! (it underflows to 0 for a d1 near the smallest double); every other key was checked above
    if (cfg%pair%gamma > 0.0_wp) then
      call check_key(reg%keys(find_key(reg, 'particles', 'diameter')), cfg%file, err)
      if (len(err) > 0) return
    end if
    call config_choices(cfg)
    call config_checks(cfg, reg, .true., err, found, derived)
    if (len(err) > 0) return
    if (present(warnings)) warnings = found
    if (present(lp)) lp = derived
  end subroutine config_load

  !> The namelist `text`, then the `overrides`, into the keys of `reg`; `err` as config_load's,
  !! from the first error, where the read stops.
  subroutine read_input(reg, text, file, overrides, err)
    type(registry_t), intent(inout) :: reg
    character(len=*), intent(in) :: text, file
    character(len=*), intent(in) :: overrides(:)
    character(len=:), allocatable, intent(out) :: err
    integer :: j
    call parse_namelist(reg, text, file, err)
    do j = 1, size(overrides)
      if (len(err) > 0) return
      if (len_trim(overrides(j)) == 0) cycle
      call apply_override(reg, overrides(j), file, err)
    end do
  end subroutine read_input

  !> How many elements the particle arrays need (>= 1): particles.count when the input gives it
  !! (file or --set) above 0, else the highest element any &particles array key is given (a
  !! scene without particles may keep unused values); 2 at least for a pair scene (expand
  !! writes particles 1 and 2). From `cfg` and `reg` after a read into arrays that grow; after
  !! one that stopped at an error, from what it read up to there.
  integer function particle_slots(cfg, reg) result(n)
    type(config_t), intent(in) :: cfg
    type(registry_t), intent(in) :: reg
    n = reg%top
    ! a count out of range gets its message from the range check after reading
    if (len(reg%keys(find_key(reg, 'particles', 'count'))%origin) > 0 .and. &
        cfg%particles%count > 0 .and. cfg%particles%count <= MAX_PARTICLES) &
      n = cfg%particles%count
    if (cfg%pair%gamma > 0.0_wp) n = max(n, 2)
    n = max(n, 1)
  end function particle_slots

  !> The second read of an input that the one read of config_load could not take as it is: an
  !! error stopped it, a value of a particle array did not convert (the read went past it), or
  !! an item selects more elements than the arrays get (an index above particles.count, a
  !! list longer than it). The messages of an index or of too many values name the size of the
  !! particle arrays, `n`, known only after reading: `cfg` goes back to its defaults with
  !! arrays of n elements, and the text and the overrides are read again into these fixed
  !! sizes, as every load read them before (some inputs then fit, e.g. x(::-1) of one element,
  !! and the load goes on). Errors are rare; only they pay for the second read.
  subroutine read_again(cfg, reg, n, text, file, overrides, err)
    type(config_t), intent(inout), target :: cfg
    type(registry_t), intent(out) :: reg
    integer, intent(in) :: n
    character(len=*), intent(in) :: text, file
    character(len=*), intent(in) :: overrides(:)
    character(len=:), allocatable, intent(out) :: err
    integer :: m
    call read_fixed(n)
    ! This read went to the end: a particles.count or &pair after the item that stopped the
    ! first read may ask for more elements than n (x(::-1) = 5 fits one element only). Once
    ! more at that size then, so that no particle lies beyond the arrays (expand, the checks).
    m = particle_slots(cfg, reg)
    if (len(err) == 0 .and. m > n) call read_fixed(m)
  contains
    subroutine read_fixed(slots)
      integer, intent(in) :: slots
      type(config_t) :: fresh
      fresh%file = cfg%file
      fresh%name = cfg%name
      cfg = fresh
      call particles_allocate(cfg%particles, slots)
      call config_registry(cfg, reg)
      call read_input(reg, text, file, overrides, err)
    end subroutine read_fixed
  end subroutine read_again

  !> Validate a configuration built or changed in code ('' if valid); `warnings` as in
  !! config_load.
  subroutine config_validate(cfg, err, warnings)
    type(config_t), intent(in) :: cfg
    character(len=:), allocatable, intent(out) :: err
    character(len=:), allocatable, intent(out), optional :: warnings
    type(lattice_params_t) :: lp
    call derive_lattice(cfg, lp, err, warnings)
  end subroutine config_validate

  !> The lattice-unit parameters of a configuration (E3, E4), checked as config_load checks:
  !! `err` is '' when `cfg` is valid, and `lp` is then set. `warnings` as in config_load.
  subroutine derive_lattice(cfg, lp, err, warnings)
    type(config_t), intent(in) :: cfg
    type(lattice_params_t), intent(out) :: lp
    character(len=:), allocatable, intent(out) :: err
    character(len=:), allocatable, intent(out), optional :: warnings
    character(len=:), allocatable :: found
    type(config_t), target :: c
    type(registry_t), target :: reg
    c = cfg
    if (.not. allocated(c%file)) c%file = ''
    call config_registry(c, reg)
    call config_choices(c)
    call config_checks(c, reg, .false., err, found, lp)
    if (len(err) > 0) found = ''
    if (present(warnings)) warnings = found
  end subroutine derive_lattice

  !> A scene file holds at least one namelist group: an empty file, or one of comments and
  !! blank lines only, would otherwise run the whole default scene without a word. (Text
  !! outside a group, and unknown groups, are the parser's to refuse.)
  subroutine config_check_text(text, file, err)
    character(len=*), intent(in) :: text, file
    character(len=:), allocatable, intent(out) :: err
    character(len=:), allocatable :: what
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
    what = 'holds only comments and blank lines'
    if (verify(text, ' '//char(9)//char(13)//NL) == 0) what = 'is empty'
    err = file//': '//what//'; a scene needs at least one '// &
          'namelist group, e.g. &domain width = 2.0 / (groups: '//config_groups()//'); every '// &
          'key with its default: dktlbm --print-defaults; examples: input/*.nml'
  end subroutine config_check_text

  !> The whole configuration as namelist text that config_load reads back: one key per line,
  !! each with '! [unit] default: ..; allowed: ..; meaning'. For --print-defaults and the
  !! output file.
  subroutine config_to_namelist(cfg, text)
    type(config_t), intent(in) :: cfg
    character(len=:), allocatable, intent(out) :: text
    type(config_t), target :: c, defaults ! `defaults` keeps its initial (default) values
    type(registry_t) :: reg, dreg
    type(text_t), allocatable :: default_texts(:)
    c = cfg
    call config_registry(c, reg)
    ! the default column lists as many elements as the value column
    call particles_allocate(defaults%particles, size(c%particles%diameter))
    call config_registry(defaults, dreg)
    call value_texts(dreg, default_texts)
    call namelist_text(reg, default_texts, text)
  end subroutine config_to_namelist

  !> The value of each key of `reg` as text, in the registry's order.
  subroutine value_texts(reg, texts)
    type(registry_t), intent(in) :: reg
    type(text_t), allocatable, intent(out) :: texts(:)
    integer :: j
    allocate (texts(size(reg%keys)))
    do j = 1, size(reg%keys)
      texts(j)%s = value_text(reg%keys(j))
    end do
  end subroutine value_texts

  !> The default texts `texts` (value_texts) taken when the particle arrays had one element,
  !! for arrays of their size now: every element starts as particle_cfg_t, so the text of n
  !! elements is that of one, n times, as value_text joins them.
  subroutine grown_defaults(reg, texts)
    type(registry_t), intent(in) :: reg
    type(text_t), intent(inout) :: texts(:)
    integer :: j
    do j = 1, size(reg%keys)
      if (reg%keys(j)%grows .and. reg%keys(j)%n > 1) &
        texts(j)%s = repeat(texts(j)%s//', ', reg%keys(j)%n - 1)//texts(j)%s
    end do
  end subroutine grown_defaults

  !> The keys of `reg` with their values, and `defaults` (value_texts of the same keys at
  !! their defaults), as namelist text (config_to_namelist).
  subroutine namelist_text(reg, defaults, text)
    type(registry_t), intent(in) :: reg
    type(text_t), intent(in) :: defaults(:)
    character(len=:), allocatable, intent(out) :: text
    character(len=:), allocatable :: line
    integer :: j
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
        text = text//line//'! ['//k%unit//'] default: '//defaults(j)%s// &
               '; allowed: '//allowed_text(k)//'; '//k%meaning//NL
      end associate
    end do
    text = text//'/'//NL
  end subroutine namelist_text

  !> A pair scene (pair.gamma > 0) sets particles 1 and 2 itself (expand): a key of theirs in
  !! &particles would be discarded, so it is refused when a --set gives it, or the file gives it
  !! a value other than its default (a file that --print-defaults wrote gives the defaults).
  subroutine pair_owns_particles(cfg, reg, defaults, err)
    type(config_t), intent(in) :: cfg
    type(registry_t), intent(in) :: reg
    type(text_t), intent(in) :: defaults(:)
    character(len=:), allocatable, intent(out) :: err
    !> the keys of &particles that &pair sets for particles 1 and 2
    character(len=8), parameter :: OWNED(8) = ['diameter', 'density ', 'x       ', &
                                               'y       ', 'u       ', 'v       ', &
                                               'omega   ', 'motion  ']
    integer :: j, idx
    err = ''
    do j = 1, size(OWNED)
      idx = find_key(reg, 'particles', trim(OWNED(j)))
      associate (k => reg%keys(idx))
        if (len(k%origin) == 0) cycle
        if (index(k%origin, '--set ') == 0 .and. value_text(k) == defaults(idx)%s) cycle
        err = blame(reg, 'particles.'//trim(OWNED(j)), cfg%file)//': &particles '// &
              trim(OWNED(j))//' = '//value_text(k)//' in a pair scene (&pair gamma = '// &
              fmt_num(cfg%pair%gamma)//'), which sets particles 1 and 2 itself and would '// &
              'discard it: diameters pair.d1 and pair.d1/pair.gamma, density pair.density, '// &
              'centres from pair.y_upper, pair.dh and pair.x_offset, free and at rest; '// &
              'allowed: leave particles.'//trim(OWNED(j))//' out and set the &pair keys, '// &
              'or pair.gamma = 0 and every particle in &particles'
        return
      end associate
    end do
  end subroutine pair_owns_particles

  !> The output directory: output%dir, or runs/<name> when it is empty.
  function config_output_dir(cfg) result(dir)
    type(config_t), intent(in) :: cfg
    character(len=:), allocatable :: dir
    dir = trim(cfg%output%dir)
    if (len(dir) == 0) dir = 'runs/'//cfg%name
  end function config_output_dir

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

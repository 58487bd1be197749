!> Differential test of the namelist reader: the files in tests/namelist/ are read twice, by the
!> compiler's own `read(unit, nml=...)` into variables declared with the real group names, keys,
!> types and array sizes of &particles, &fluid, &lbm, &run, &output and &window, and by
!> config_load (dkt_namelist through dkt_config); every value must agree, reals bit for bit.
!>
!> Bugs it catches: any way in which the program's reader departs from Fortran's namelist rules
!> for these forms, e.g. a repeat count or a null value applied to the wrong elements, a stride
!> or a negative stride off by one, an element list that does not go on to the next elements, a
!> doubled quote or a string continued over lines read wrongly, a logical form misread, a real
!> converted to a different double (rounding, exponent without a letter, -0.0, subnormals), a
!> group given twice applied once.
!>
!> Forms left out because gfortran (12) itself departs from the standard there (test_config
!> covers them): the logicals `true`/`false` and other words starting with T or F without a
!> leading '.', except a lone T/F; a section with an omitted bound and a stride (x(::2)); a
!> section whose upper bound lies outside the array while its elements do not (x(2:18:7)); a
!> comma that starts a line after a value (gfortran reads a null value there). Also left out:
!> the program's extensions, unquoted strings and blanks in or before an index.
!>
!> Usage: test_namelist_compiler DIR (the folder of the .nml files).
program test_namelist_compiler
  use, intrinsic :: iso_fortran_env, only: int64
  use dkt_kinds, only: wp
  use dkt_config, only: config_t, particles_cfg_t, config_load, read_text_file, particles_allocate
  use dkt_text, only: lower_case
  use dkt_check, only: check, finish
  implicit none

  character(len=12), parameter :: FILES(4) = ['arrays.nml  ', 'syntax.nml  ', 'strings.nml ', &
                                              'numbers.nml ']
  character(len=1) :: none(0)
  character(len=512) :: dir
  character(len=:), allocatable :: path, text, err
  type(config_t) :: def, cfg
  integer :: j
  !> Elements of each particle array for read(nml=): the highest index the files give. config_load
  !! sizes its arrays to that index (no particles.count in the files), so a section with an open
  !! bound (v(:), omega(3:)) covers the same elements for both readers.
  integer, parameter :: NSLOT = 16

  call get_command_argument(1, dir)
  if (len_trim(dir) == 0) error stop 'usage: test_namelist_compiler DIR'
  call config_load(def, '', 'defaults.nml', none, err) ! both readers start from the defaults
  if (len(err) > 0) error stop 'the defaults are refused'
  do j = 1, size(FILES)
    path = trim(dir)//'/'//trim(FILES(j))
    call read_text_file(path, text, err)
    if (len(err) == 0) call config_load(cfg, text, path, none, err)
    call expect(trim(FILES(j))//': accepted by config_load', len(err) == 0, err)
    if (len(err) > 0) cycle
    call compare_particles(path, def, cfg)
    call compare_fluid(path, def, cfg)
    call compare_lbm(path, def, cfg)
    call compare_run(path, def, cfg)
    call compare_output(path, def, cfg)
    call compare_window(path, def, cfg)
  end do
  call finish()

contains

  !> A check whose failure prints what differed.
  subroutine expect(name, ok, detail)
    character(len=*), intent(in) :: name, detail
    logical, intent(in) :: ok
    if (.not. ok .and. len(detail) > 0) write (*, '(a)') '  '//detail
    call check(name, ok, merge(0.0_wp, 1.0_wp, ok))
  end subroutine expect

  !> Open `path` for the compiler's reader; false (and a failed check) if it cannot.
  logical function open_file(path, unit) result(ok)
    character(len=*), intent(in) :: path
    integer, intent(out) :: unit
    integer :: ios
    open (newunit=unit, file=path, status='old', action='read', iostat=ios)
    ok = ios == 0
    if (.not. ok) call expect(path//': opened', .false., 'cannot open')
  end function open_file

  !> After read(nml=) of one occurrence: true to read on, false at the end of the file;
  !! a read error is a failed check naming the group.
  logical function read_on(path, group, ios, msg)
    character(len=*), intent(in) :: path, group, msg
    integer, intent(in) :: ios
    read_on = ios == 0
    if (ios > 0) call expect(path//' &'//group//': read by read(nml=)', .false., trim(msg))
  end function read_on

  !> Reals equal bit for bit (so -0.0 /= 0.0 and every rounding shows).
  elemental logical function same(a, b)
    real(wp), intent(in) :: a, b
    same = transfer(a, 0_int64) == transfer(b, 0_int64)
  end function same

  subroutine reals(path, what, a, b)
    character(len=*), intent(in) :: path, what
    real(wp), intent(in) :: a(:), b(:)
    character(len=100) :: diff
    integer :: k
    k = findloc(same(a, b), .false., dim=1)
    diff = ''
    if (k > 0) write (diff, '(a,i0,a,es24.16e3,a,es24.16e3)') 'element ', k, ': read(nml=)', &
      a(k), ', dktlbm', b(k)
    call expect(path//' '//what//' bit for bit', k == 0, trim(diff))
  end subroutine reals

  subroutine compare_particles(path, def, cfg)
    character(len=*), intent(in) :: path
    type(config_t), intent(in) :: def, cfg
    integer :: count, u_nml, ios, k
    logical :: ok
    real(wp), dimension(:), allocatable :: diameter, density, x, y, u, v, omega
    ! fixed size: gfortran 12 -Wall takes an allocatable character array assigned from d%motion
    ! for possibly uninitialised, and the CI build treats warnings as errors
    character(len=16) :: motion(NSLOT)
    real(wp) :: gravity
    character(len=256) :: msg
    type(particles_cfg_t) :: d, p
    character(len=100) :: detail
    namelist /particles/ count, diameter, density, x, y, u, v, omega, motion, gravity
    ! config_load sized the defaults to 1 element: each further element takes the same default
    d = def%particles
    call particles_allocate(d, NSLOT)
    count = d%count
    diameter = d%diameter
    density = d%density
    x = d%x
    y = d%y
    u = d%u
    v = d%v
    omega = d%omega
    motion = d%motion
    gravity = d%gravity
    if (.not. open_file(path, u_nml)) return
    do ! every occurrence of the group, in order, as config_load applies them
      read (u_nml, nml=particles, iostat=ios, iomsg=msg)
      if (.not. read_on(path, 'particles', ios, msg)) exit
    end do
    close (u_nml)
    ! The program's arrays end at the highest index given: no longer than read(nml=)'s; the
    ! elements past their end must have kept the defaults in read(nml=)'s arrays.
    write (detail, '(a,i0,a,i0)') 'config_load made ', size(cfg%particles%diameter), &
      ' elements, more than ', NSLOT
    call expect(path//' &particles arrays no longer than the highest index', &
                size(cfg%particles%diameter) <= NSLOT, trim(detail))
    p = cfg%particles
    call particles_allocate(p, NSLOT)
    call expect(path//' &particles count', count == p%count, '')
    call reals(path, '&particles diameter', diameter, p%diameter)
    call reals(path, '&particles density', density, p%density)
    call reals(path, '&particles x', x, p%x)
    call reals(path, '&particles y', y, p%y)
    call reals(path, '&particles u', u, p%u)
    call reals(path, '&particles v', v, p%v)
    call reals(path, '&particles omega', omega, p%omega)
    call reals(path, '&particles gravity', [gravity], [p%gravity])
    ! choices are stored in lower case by the program
    ok = .true.
    do k = 1, size(motion)
      ok = ok .and. lower_case(motion(k)) == p%motion(k)
    end do
    call expect(path//' &particles motion', ok, '')
  end subroutine compare_particles

  subroutine compare_fluid(path, def, cfg)
    character(len=*), intent(in) :: path
    type(config_t), intent(in) :: def, cfg
    real(wp) :: density, viscosity, body_force(2)
    integer :: u_nml, ios
    character(len=256) :: msg
    namelist /fluid/ density, viscosity, body_force
    density = def%fluid%density
    viscosity = def%fluid%viscosity
    body_force = def%fluid%body_force
    if (.not. open_file(path, u_nml)) return
    do
      read (u_nml, nml=fluid, iostat=ios, iomsg=msg)
      if (.not. read_on(path, 'fluid', ios, msg)) exit
    end do
    close (u_nml)
    call reals(path, '&fluid density, viscosity, body_force', [density, viscosity, body_force], &
               [cfg%fluid%density, cfg%fluid%viscosity, cfg%fluid%body_force])
  end subroutine compare_fluid

  subroutine compare_lbm(path, def, cfg)
    character(len=*), intent(in) :: path
    type(config_t), intent(in) :: def, cfg
    real(wp) :: dx, tau, s_e, s_eps, s_q, cells_per_diameter
    character(len=8) :: collision
    integer :: u_nml, ios
    character(len=256) :: msg
    namelist /lbm/ dx, tau, collision, s_e, s_eps, s_q, cells_per_diameter
    dx = def%lbm%dx
    tau = def%lbm%tau
    collision = def%lbm%collision
    s_e = def%lbm%s_e
    s_eps = def%lbm%s_eps
    s_q = def%lbm%s_q
    cells_per_diameter = def%lbm%cells_per_diameter
    if (.not. open_file(path, u_nml)) return
    do
      read (u_nml, nml=lbm, iostat=ios, iomsg=msg)
      if (.not. read_on(path, 'lbm', ios, msg)) exit
    end do
    close (u_nml)
    call reals(path, '&lbm dx, tau, s_e, s_eps, s_q, cells_per_diameter', &
               [dx, tau, s_e, s_eps, s_q, cells_per_diameter], &
               [cfg%lbm%dx, cfg%lbm%tau, cfg%lbm%s_e, cfg%lbm%s_eps, cfg%lbm%s_q, &
                cfg%lbm%cells_per_diameter])
    call expect(path//' &lbm collision', lower_case(collision) == cfg%lbm%collision, &
                collision//' /= '//cfg%lbm%collision)
  end subroutine compare_lbm

  subroutine compare_run(path, def, cfg)
    character(len=*), intent(in) :: path
    type(config_t), intent(in) :: def, cfg
    real(wp) :: t_end, t_ref, mach_limit, checkpoint_wall, wall_limit
    integer :: steps, progress_every, guard_every, checkpoint_every, checkpoint_keep
    integer :: u_nml, ios
    character(len=256) :: msg
    namelist /run/ t_end, steps, t_ref, progress_every, guard_every, mach_limit, &
      checkpoint_every, checkpoint_wall, checkpoint_keep, wall_limit
    t_end = def%run%t_end
    steps = def%run%steps
    t_ref = def%run%t_ref
    progress_every = def%run%progress_every
    guard_every = def%run%guard_every
    mach_limit = def%run%mach_limit
    checkpoint_every = def%run%checkpoint_every
    checkpoint_wall = def%run%checkpoint_wall
    checkpoint_keep = def%run%checkpoint_keep
    wall_limit = def%run%wall_limit
    if (.not. open_file(path, u_nml)) return
    do
      read (u_nml, nml=run, iostat=ios, iomsg=msg)
      if (.not. read_on(path, 'run', ios, msg)) exit
    end do
    close (u_nml)
    call reals(path, '&run t_end, t_ref, mach_limit, checkpoint_wall, wall_limit', &
               [t_end, t_ref, mach_limit, checkpoint_wall, wall_limit], &
               [cfg%run%t_end, cfg%run%t_ref, cfg%run%mach_limit, cfg%run%checkpoint_wall, &
                cfg%run%wall_limit])
    call expect(path//' &run integers', all([steps, progress_every, guard_every, &
                                             checkpoint_every, checkpoint_keep] == &
                                            [cfg%run%steps, cfg%run%progress_every, &
                                             cfg%run%guard_every, cfg%run%checkpoint_every, &
                                             cfg%run%checkpoint_keep]), '')
  end subroutine compare_run

  subroutine compare_output(path, def, cfg)
    character(len=*), intent(in) :: path
    type(config_t), intent(in) :: def, cfg
    character(len=256) :: dir
    real(wp) :: field_interval, series_interval
    logical :: overwrite
    integer :: u_nml, ios
    character(len=256) :: msg
    namelist /output/ dir, field_interval, series_interval, overwrite
    dir = def%output%dir
    field_interval = def%output%field_interval
    series_interval = def%output%series_interval
    overwrite = def%output%overwrite
    if (.not. open_file(path, u_nml)) return
    do
      read (u_nml, nml=output, iostat=ios, iomsg=msg)
      if (.not. read_on(path, 'output', ios, msg)) exit
    end do
    close (u_nml)
    call expect(path//' &output dir', dir == cfg%output%dir, '['//trim(dir)//'] /= ['// &
                trim(cfg%output%dir)//']')
    call reals(path, '&output field_interval, series_interval', &
               [field_interval, series_interval], &
               [cfg%output%field_interval, cfg%output%series_interval])
    call expect(path//' &output overwrite', overwrite .eqv. cfg%output%overwrite, '')
  end subroutine compare_output

  subroutine compare_window(path, def, cfg)
    character(len=*), intent(in) :: path
    type(config_t), intent(in) :: def, cfg
    logical :: enabled
    real(wp) :: below, above, margin
    integer :: u_nml, ios
    character(len=256) :: msg
    namelist /window/ enabled, below, above, margin
    enabled = def%window%enabled
    below = def%window%below
    above = def%window%above
    margin = def%window%margin
    if (.not. open_file(path, u_nml)) return
    do
      read (u_nml, nml=window, iostat=ios, iomsg=msg)
      if (.not. read_on(path, 'window', ios, msg)) exit
    end do
    close (u_nml)
    call expect(path//' &window enabled', enabled .eqv. cfg%window%enabled, '')
    call reals(path, '&window below, above, margin', [below, above, margin], &
               [cfg%window%below, cfg%window%above, cfg%window%margin])
  end subroutine compare_window

end program test_namelist_compiler

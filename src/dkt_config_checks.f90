!> The checks of a configuration at t = 0 that need no lattice units: the domain's ends, each
!> channel length in whole cells, each particle (velocity of a fixed one, position, cells per
!> diameter, gap to a wall), overlaps, the pair's distance and the window. Each check is one
!> procedure `chk_<what>` that sets `err` (one message naming where the keys were set, the
!> value and what is allowed) or adds a warning; dkt_config_checks_run holds the others and
!> the sequence of all.
module dkt_config_checks
  use ieee_arithmetic, only: ieee_is_finite
  use dkt_kinds, only: wp
  use dkt_registry, only: registry_t, find_key, value_text, origin_of, blame
  use dkt_text, only: quoted, fmt_real, fmt_num, itoa
  use dkt_config_types, only: config_t
  use dkt_config_scene, only: largest_diameter, window_bottom, dx_knob, WINDOW_AUTO_CAP
  use dkt_config_lattice, only: lattice_params_t
  implicit none
  private
  public :: check_t, chk_domain, chk_particles, chk_contacts, chk_pair, chk_window
  public :: val, src, from, item, dx_text, power, round6, round_up

  !> What the checks of one configuration share: the configuration and its registry (for the
  !! values as typed and where they were set), the lattice units once derived, the warnings
  !! so far and the particles warned about.
  type :: check_t
    type(config_t), pointer :: c => null()
    type(registry_t), pointer :: reg => null()
    type(lattice_params_t) :: lp       !! set before the checks that need lattice units
    character(len=:), allocatable :: warnings !! newline-separated, '' if none
    integer :: few_cells = 0 !! particles with too few cells per diameter (warned)
    integer :: near_wall = 0 !! free particles too near a wall (warned)
    !> cm: the longest the window may become (its height, or more when window.max_above lets
    !! it grow), set by chk_particles for the bound on absolute positions
    real(wp) :: window_length = 0.0_wp
  end type check_t

  real(wp), parameter :: WHOLE_TOL = 1.0e-6_wp !! how close width/dx must be to a whole number
  real(wp), parameter :: MAX_CELLS = 1.0e9_wp  !! more cells on one axis is surely a typing error
  real(wp), parameter :: MIN_CELLS_PER_D = 4.0_wp  !! fewer cells per diameter: refused
  real(wp), parameter :: GOOD_CELLS_PER_D = 8.0_wp !! fewer cells per diameter: a warning
  real(wp), parameter, public :: CONTACT_TOL = 1.0e-12_wp  !! relative round-off of a typed distance
  integer, parameter :: WARN_EACH = 10 !! warnings naming a particle, then one line counting
  character(len=*), parameter :: NL = new_line('a')

contains

  !> The domain: both ends periodic or neither, a Taylor-Green flow in a periodic box, no
  !! particles with periodic sides or ends, and whole cells across and along the channel.
  subroutine chk_domain(ck, err)
    type(check_t), intent(inout), target :: ck
    character(len=:), allocatable, intent(inout) :: err
    type(config_t), pointer :: c
    c => ck%c
    associate (d => c%domain)
      if ((d%lower == 'periodic') .neqv. (d%upper == 'periodic')) then
        err = from(ck, 'domain.'//merge('lower', 'upper', d%lower == 'periodic')// &
                   ' domain.lower domain.upper')// &
              ': &domain lower = '//val(ck, 'domain', 'lower')//' and upper = '// &
              val(ck, 'domain', 'upper')//': a periodic channel needs both ends periodic; '// &
              'set lower and upper both to ''periodic'', or neither'
        return
      end if
      if (c%initial%flow == 'taylor_green' .and. &
          any([d%sides, d%lower, d%upper] /= 'periodic')) then
        err = from(ck, 'initial.flow domain.sides domain.lower domain.upper')// &
              ': &initial flow = ''taylor_green'' needs a periodic '// &
              'domain, but &domain sides = '//val(ck, 'domain', 'sides')//', lower = '// &
              val(ck, 'domain', 'lower')//', upper = '//val(ck, 'domain', 'upper')// &
              '; set all three to ''periodic'''
        return
      end if
      ! a particle would leave through a periodic side or end: not supported yet
      if (c%particles%count > 0 .and. any([d%sides, d%lower] == 'periodic')) then
        err = from(ck, 'particles.count domain.sides domain.lower')//': &particles count = '// &
              val(ck, 'particles', 'count')//' with &domain sides = '// &
              val(ck, 'domain', 'sides')// &
              ', lower = '//val(ck, 'domain', 'lower')//': particles need walls or open ends; '// &
              'periodic sides or ends are for particle-free scenes'
        return
      end if
      call chk_cells(ck, err, 'width', 'nx', d%width)
      if (len(err) > 0) return
      call chk_cells(ck, err, 'height', 'ny', d%height)
      if (len(err) > 0) return
    end associate
  end subroutine chk_domain

  !> Every particle (chk_particle), then one line counting the warnings past the first
  !! WARN_EACH of each kind: a scene may hold 10^5 particles.
  subroutine chk_particles(ck, err)
    type(check_t), intent(inout), target :: ck
    character(len=:), allocatable, intent(inout) :: err
    integer :: j
    real(wp) :: above
    ck%few_cells = 0
    ck%near_wall = 0
    ck%window_length = ck%c%domain%height
    if (ck%c%window%enabled) then
      ! the longest the window may grow: its limit, or for the default -1 (window_max_above,
      ! which needs the scene's velocity scale, not yet checked here) the cap of that limit
      above = ck%c%window%max_above
      if (above < 0.0_wp) above = WINDOW_AUTO_CAP*ck%c%window%above
      ck%window_length = max(ck%window_length, (ck%c%window%below + above)* &
                             largest_diameter(ck%c))
    end if
    do j = 1, ck%c%particles%count
      call chk_particle(ck, err, j)
      if (len(err) > 0) return
    end do
    ! a scene of many disks: the first WARN_EACH of each kind of warning, then a count
    if (ck%few_cells > WARN_EACH) &
      ck%warnings = ck%warnings//NL//from(ck, 'lbm.dx particles.diameter')//': '// &
                    itoa(ck%few_cells - WARN_EACH)//' more particles have fewer than '// &
                    itoa(nint(GOOD_CELLS_PER_D))//' cells per diameter'
    if (ck%near_wall > WARN_EACH) &
      ck%warnings = ck%warnings//NL//from(ck, 'particles.x particles.y lbm.dx')//': '// &
                    itoa(ck%near_wall - WARN_EACH)//' more free particles start with '// &
                    'their surface less than dx from a wall'
  end subroutine chk_particles

  !> length/dx must be a whole number (within WHOLE_TOL) of at least 3 cells: the lattice
  !! would otherwise silently change the channel's size, and a channel needs interior cells.
  subroutine chk_cells(ck, err, key, axis, length)
    type(check_t), intent(inout), target :: ck
    character(len=:), allocatable, intent(inout) :: err
    character(len=*), intent(in) :: key, axis
    real(wp), intent(in) :: length
    real(wp) :: r
    character(len=:), allocatable :: both
    type(config_t), pointer :: c
    c => ck%c
    r = length/c%lbm%dx
    both = from(ck, 'lbm.dx domain.'//key//' lbm.cells_per_diameter')//': &domain '//key//' = '// &
           val(ck, 'domain', key)//' and &lbm dx = '//val(ck, 'lbm', 'dx')//' give '
    if (r >= MAX_CELLS) then
      err = both//axis//' = '//key//'/dx = '//fmt_num(r)//' cells; allowed: fewer than '// &
            fmt_num(MAX_CELLS)//'; '//dx_knob(c, larger=.true.)
    else if (nint(r) < 3) then
      err = both//axis//' = nint('//key//'/dx) = '//itoa(nint(r))//' cells; allowed: '// &
            axis//' >= 3; '//dx_knob(c)
      if (c%lbm%cells_per_diameter <= 0.0_wp) err = err//', e.g. dx = '//fmt_real(length/3.0_wp)
    else if (abs(r - anint(r)) > WHOLE_TOL) then
      ! the suggestion is to be copied: all its digits, so that it gives whole cells. Where
      ! lbm.cells_per_diameter sets dx (from the width), lbm.dx is not read: the length moves.
      if (c%lbm%cells_per_diameter > 0.0_wp) then
        err = both//key//'/dx = '//fmt_num(r)//' cells, not a whole number; with dx set by '// &
              'lbm.cells_per_diameter, choose '//key//' = n*dx, e.g. '//key//' = '// &
              fmt_real(anint(r)*c%lbm%dx)//' ('//itoa(nint(r))//' cells)'
      else
        err = both//key//'/dx = '//fmt_num(r)//' cells, not a whole number; choose dx = '// &
              key//'/n, e.g. dx = '//fmt_real(length/anint(r))//' ('//itoa(nint(r))//' cells)'
      end if
    end if
  end subroutine chk_cells

  !> Particle k at t = 0: a fixed particle has no velocity, its centre lies in the channel
  !! at least one radius from every wall (touching a wall is an overlap: the bounce-back
  !! and the repulsion of E11 would start from a degenerate contact), and its diameter spans
  !! enough lattice cells for the boundary links of E6-E7 (docs/model.md §3).
  subroutine chk_particle(ck, err, k)
    type(check_t), intent(inout), target :: ck
    character(len=:), allocatable, intent(inout) :: err
    integer, intent(in) :: k
    real(wp) :: cells
    character(len=:), allocatable :: key, both
    type(config_t), pointer :: c
    c => ck%c
    associate (p => c%particles, d => c%domain)
      if (p%motion(k) == 'fixed') then
        key = ''
        if (abs(p%omega(k)) > 0.0_wp) key = 'omega'
        if (abs(p%v(k)) > 0.0_wp) key = 'v'
        if (abs(p%u(k)) > 0.0_wp) key = 'u'
        if (len(key) > 0) then
          err = src(ck, key, 'particles')//': &particles motion('//itoa(k)//') = ''fixed'' and '// &
                item(key, k, merge(p%u(k), merge(p%v(k), p%omega(k), key == 'v'), key == 'u'))// &
                ': a fixed particle does not move, so its velocity is not used; allowed: '// &
                'u('//itoa(k)//') = v('//itoa(k)//') = omega('//itoa(k)//') = 0 with '// &
                'motion = ''fixed''; set them to 0, or use motion = ''prescribed'' to keep '// &
                'the particle moving at that velocity'
          return
        end if
      end if
      call chk_position(ck, err, 'x', k, p%x(k), 'width', d%width, d%sides == 'wall', &
                        d%sides == 'wall', '&domain sides = '//quoted(trim(d%sides)))
      if (len(err) > 0) return
      if (.not. c%window%enabled) then
        ! an end at rest, a 'wall' or a 'velocity' end at zero velocity, is a wall for E11
        call chk_position(ck, err, 'y', k, p%y(k), 'height', d%height, d%lower == 'wall' .or. &
                          (d%lower == 'velocity' .and. c%inlet%velocity == 0.0_wp), &
                          d%upper == 'wall' .or. &
                          (d%upper == 'velocity' .and. c%inlet%velocity == 0.0_wp), &
                          '&domain lower = '//quoted(trim(d%lower))//', upper = '// &
                          quoted(trim(d%upper))//', &inlet velocity = '// &
                          val(ck, 'inlet', 'velocity'))
        if (len(err) > 0) return
      else if (abs(p%y(k)) > 2.0_wp**31*c%lbm%dx - ck%window_length) then
        ! docs/model.md §5: the window and its particles stay within 2^31 spacings of y = 0,
        ! where a double resolves the position to 2^-21 dx; further out a step's motion is lost
        err = from(ck, 'particles.y pair.y_upper lbm.dx lbm.cells_per_diameter window.below '// &
                   'window.above window.max_above')//': &particles y('//itoa(k)//') = '// &
              fmt_num(p%y(k))// &
              ' cm (or &pair y_upper) in a window scene with dx = '//fmt_num(c%lbm%dx)// &
              ' cm: too far from y = 0 for the absolute positions to resolve a step''s '// &
              'motion; allowed: |y('//itoa(k)//')| <= 2^31 dx - window length = '// &
              fmt_num(round6(2.0_wp**31*c%lbm%dx - ck%window_length, down=.true.))//' cm'
        return
      end if

      cells = p%diameter(k)/c%lbm%dx
      ! the message is built only when it is used: a scene may hold 10^5 particles
      if (cells < MIN_CELLS_PER_D - WHOLE_TOL .or. &
          (cells < GOOD_CELLS_PER_D - WHOLE_TOL .and. ck%few_cells < WARN_EACH)) &
        both = from(ck, 'lbm.dx particles.diameter lbm.cells_per_diameter')//': '// &
               item('diameter', k, p%diameter(k))//' and &lbm dx = '//val(ck, 'lbm', 'dx')// &
               ' give '//fmt_num(cells)//' cells per diameter'
      if (cells < MIN_CELLS_PER_D - WHOLE_TOL) then
        err = both//'; allowed: diameter('//itoa(k)//')/dx >= '// &
              itoa(nint(MIN_CELLS_PER_D))//', i.e. dx <= diameter('//itoa(k)//')/'// &
              itoa(nint(MIN_CELLS_PER_D))//' = '// &
              fmt_num(p%diameter(k)/MIN_CELLS_PER_D)//' cm; '//dx_knob(c)
      else if (cells < GOOD_CELLS_PER_D - WHOLE_TOL) then
        ! the first WARN_EACH such particles are named; the others are counted (below)
        ck%few_cells = ck%few_cells + 1
        if (ck%few_cells <= WARN_EACH) then
          if (len(ck%warnings) > 0) ck%warnings = ck%warnings//NL
          ck%warnings = ck%warnings//both//', fewer than '//itoa(nint(GOOD_CELLS_PER_D))// &
                        ': the force on particle '//itoa(k)//' and its motion will be '// &
                        'inaccurate; dx <= diameter('//itoa(k)//')/'// &
                        itoa(nint(GOOD_CELLS_PER_D))//' = '// &
                        fmt_num(p%diameter(k)/GOOD_CELLS_PER_D)//' cm gives '// &
                        itoa(nint(GOOD_CELLS_PER_D))
        end if
      end if
      call chk_wall_gap(ck, k)
    end associate
  end subroutine chk_particle

  !> A warning for a free particle whose surface starts less than one lattice spacing from a
  !! wall. Measured (docs/stability.md): input/single.nml at 10 spacings per diameter with the
  !! surface 0.49 and 0.5 spacings from the side wall was stopped by the Mach guard after
  !! 370-420 steps in the gap's flow, at 0.2, 0.75 and 1 spacing it ran through.
  subroutine chk_wall_gap(ck, k)
    type(check_t), intent(inout), target :: ck
    integer, intent(in) :: k
    real(wp) :: gap(4), r
    logical :: wall(4)
    character(len=*), parameter :: NAMES(4) = &
                                   [character(len=12) :: 'x = 0', 'x = width', 'y = 0', &
                                                          'y = height']
    integer :: j
    type(config_t), pointer :: c
    c => ck%c
    associate (p => c%particles, d => c%domain)
      if (p%motion(k) /= 'free') return
      r = 0.5_wp*p%diameter(k)
      gap = [p%x(k) - r, d%width - p%x(k) - r, p%y(k) - r, d%height - p%y(k) - r]
      wall = [d%sides == 'wall', d%sides == 'wall', &
              d%lower == 'wall' .and. .not. c%window%enabled, &
              d%upper == 'wall' .and. .not. c%window%enabled]
      do j = 1, size(gap)
        if (.not. wall(j) .or. gap(j) >= c%lbm%dx*(1.0_wp - CONTACT_TOL)) cycle
        ck%near_wall = ck%near_wall + 1
        if (ck%near_wall > WARN_EACH) return
        if (len(ck%warnings) > 0) ck%warnings = ck%warnings//NL
        ck%warnings = ck%warnings//from(ck, 'particles.x particles.y lbm.dx')//': particle '// &
                      itoa(k)//' starts with its surface '//fmt_num(round6(gap(j)/c%lbm%dx))// &
                      ' lattice spacings from the wall at '//trim(NAMES(j))//' (dx = '// &
                      fmt_num(c%lbm%dx)//' cm); a disk started half a spacing from a wall '// &
                      'was measured to be stopped by the Mach guard in the gap''s flow '// &
                      '(docs/stability.md); start it at least dx from the wall'
        return
      end do
    end associate
  end subroutine chk_wall_gap

  !> Coordinate `key` = `pos` of the centre of particle k within 0..length (`dim`); a wall
  !! at the low (`lo_wall`) or high end (`hi_wall`) must be more than one radius away.
  subroutine chk_position(ck, err, key, k, pos, dim, length, lo_wall, hi_wall, ends)
    type(check_t), intent(inout), target :: ck
    character(len=:), allocatable, intent(inout) :: err
    character(len=*), intent(in) :: key, dim, ends
    integer, intent(in) :: k
    real(wp), intent(in) :: pos, length
    logical, intent(in) :: lo_wall, hi_wall
    real(wp) :: r, lo, hi
    character(len=:), allocatable :: head, allowed, what
    type(config_t), pointer :: c
    c => ck%c
    r = 0.5_wp*c%particles%diameter(k)
    lo = merge(r, 0.0_wp, lo_wall)
    hi = merge(length - r, length, hi_wall)
    if ((pos > lo .or. (.not. lo_wall .and. pos >= lo)) .and. &
        (pos < hi .or. (.not. hi_wall .and. pos <= hi))) return
    head = from(ck, 'particles.'//key//' particles.diameter domain.'//dim//' domain.sides '// &
                'domain.lower domain.upper')//': '//item(key, k, pos)//' with '// &
           item('diameter', k, c%particles%diameter(k))//', &domain '//dim//' = '// &
           val(ck, 'domain', dim)//' and '//ends//': '
    allowed = fmt_num(lo)//trim(merge(' < ', ' <=', lo_wall))//' '//key//'('//itoa(k)// &
              ')'//trim(merge(' < ', ' <=', hi_wall))//' '//fmt_num(hi)
    if (lo >= hi) then
      err = head//'particle '//itoa(k)//' is not narrower than the channel between its '// &
            'walls; allowed: diameter('//itoa(k)//') < '//dim//' = '//val(ck, 'domain', dim)
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
  end subroutine chk_position

  !> No two particles overlap at t = 0: the distance of their centres is at least the sum of
  !! their radii (E10 would otherwise start with its overlap branch). Touching is allowed, to
  !! within round-off (CONTACT_TOL), so that centres typed exactly one contact distance apart
  !! are accepted.
  subroutine chk_contacts(ck, err)
    type(check_t), intent(inout), target :: ck
    character(len=:), allocatable, intent(inout) :: err
    real(wp) :: gx, gy, dist, contact
    integer :: k, m
    type(config_t), pointer :: c
    c => ck%c
    ! E13 takes gaps from h_min up to its cut-off h_c
    if (c%collision%lubrication .and. &
        .not. (c%collision%lubrication_min < c%collision%lubrication_range)) then
      err = from(ck, 'collision.lubrication_min collision.lubrication_range')// &
            ': &collision lubrication_min = '//val(ck, 'collision', 'lubrication_min')// &
            ' is not below lubrication_range = '//val(ck, 'collision', 'lubrication_range')// &
            ' (lattice spacings); allowed: lubrication_min < lubrication_range'
      return
    end if
    associate (p => c%particles)
      call first_overlap(p%x(1:p%count), p%y(1:p%count), p%diameter(1:p%count), k, m)
      if (k == 0) return
      gx = p%x(m) - p%x(k)
      gy = p%y(m) - p%y(k)
      dist = hypot(gx, gy)
      contact = 0.5_wp*(p%diameter(k) + p%diameter(m))
      err = from(ck, 'particles.y particles.x particles.diameter')// &
            ': &particles: particles '//itoa(k)//' and '//itoa(m)//' overlap at t = 0: '// &
            pair_text(ck, 'x', k, m)//', '//pair_text(ck, 'y', k, m)//', '// &
            pair_text(ck, 'diameter', k, m)//': the distance of the centres '//fmt_num(dist)// &
            ' cm is less than the contact distance (diameter('//itoa(k)// &
            ') + diameter('//itoa(m)//'))/2 = '//fmt_num(contact)//' cm; allowed: '// &
            'a distance of at least '//fmt_num(contact)//' cm; move them apart'
    end associate
  end subroutine chk_contacts

  !> D_h leaves a gap wider than the contact range of E10 between the pair's surfaces: a
  !! pair that starts inside the range starts in contact, and drafting is never seen.
  subroutine chk_pair(ck, err)
    type(check_t), intent(inout), target :: ck
    character(len=:), allocatable, intent(inout) :: err
    real(wp) :: contact, dh_min
    type(config_t), pointer :: c
    c => ck%c
    associate (q => c%pair)
      contact = 0.5_wp*q%d1*(1.0_wp + 1.0_wp/q%gamma) + c%collision%range*c%lbm%dx
      dh_min = contact/q%d1
      if (q%dh*q%d1 <= contact*(1.0_wp + CONTACT_TOL)) &
        err = from(ck, 'pair.dh pair.d1 pair.gamma collision.range lbm.dx '// &
                   'lbm.cells_per_diameter')//': &pair dh = '//val(ck, 'pair', 'dh')// &
              ' gives D_h = '// &
              fmt_num(q%dh*q%d1)//' cm with d1 = '//val(ck, 'pair', 'd1')//', gamma = '// &
              val(ck, 'pair', 'gamma')//': the pair starts within the contact distance '// &
              '(D_1 + D_2)/2 + collision.range dx = '//fmt_num(contact)//' cm; allowed: '// &
              'dh > '//fmt_num(round_up(dh_min))
    end associate
  end subroutine chk_pair

  !> A growing window's limit is not below its length (window.max_above), and every particle
  !! lies inside the window at t = 0, below its upper end by the margin.
  subroutine chk_window(ck, err)
    type(check_t), intent(inout), target :: ck
    character(len=:), allocatable, intent(inout) :: err
    real(wp) :: y_lo, y_hi, top, d1, need
    integer :: k
    type(config_t), pointer :: c
    c => ck%c
    associate (p => c%particles, win => c%window)
      if (win%max_above > 0.0_wp .and. win%max_above < win%above) then
        err = from(ck, 'window.max_above window.above')//': &window max_above = '// &
              val(ck, 'window', 'max_above')//' D_1 is below above = '// &
              val(ck, 'window', 'above')//' D_1: the window would shrink; allowed: '// &
              'max_above = -1 (it grows as the run needs), 0 (it never grows) or '// &
              'max_above >= above'
        return
      end if
      d1 = largest_diameter(c)
      y_lo = window_bottom(c)
      y_hi = y_lo + c%domain%height
      do k = 1, p%count
        top = p%y(k) + 0.5_wp*p%diameter(k) + win%margin*d1
        if (top > y_hi .or. p%y(k) - 0.5_wp*p%diameter(k) < y_lo) then
          need = (top - minval(p%y(1:p%count), mask=p%motion(1:p%count) == 'free'))/d1
          err = from(ck, 'window.above window.margin particles.y particles.diameter pair.dh '// &
                     'pair.y_upper pair.d1 pair.gamma')//': &window above = '// &
                val(ck, 'window', 'above')// &
                ' D_1 (D_1 = '//fmt_num(d1)//' cm) cannot hold the particles: the window '// &
                'spans y = '//fmt_num(y_lo)//' .. '//fmt_num(y_hi)//' cm, but particle '// &
                itoa(k)//' (y = '//fmt_num(p%y(k))//', diameter '// &
                fmt_num(p%diameter(k))//') with the margin of '//val(ck, 'window', 'margin')// &
                ' D_1 reaches '//fmt_num(top)//' cm; allowed: above >= '// &
                fmt_num(round_up(need))
          return
        end if
      end do
    end associate
  end subroutine chk_window

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

  !> '&lbm dx = ..' or '&lbm cells_per_diameter = .. (dx = .. cm)', whichever set dx
  function dx_text(ck) result(s)
    type(check_t), intent(in) :: ck
    character(len=:), allocatable :: s
    if (ck%c%lbm%cells_per_diameter > 0.0_wp) then
      s = '&lbm cells_per_diameter = '//val(ck, 'lbm', 'cells_per_diameter')//' (dx = '// &
          fmt_num(ck%c%lbm%dx)//' cm)'
    else
      s = '&lbm dx = '//val(ck, 'lbm', 'dx')
    end if
  end function dx_text

  !> The value of key g.k as text
  function val(ck, g, k) result(s)
    type(check_t), intent(in) :: ck
    character(len=*), intent(in) :: g, k
    character(len=:), allocatable :: s
    s = value_text(ck%reg%keys(find_key(ck%reg, g, k)))
  end function val

  !> Where key g.k was set (origin_of)
  function src(ck, k, g) result(s)
    type(check_t), intent(in) :: ck
    character(len=*), intent(in) :: k, g
    character(len=:), allocatable :: s
    s = origin_of(ck%reg, g, k, ck%c%file)
  end function src

  !> The origin of a message on the keys 'group.key ...' (blame)
  function from(ck, keys) result(s)
    type(check_t), intent(in) :: ck
    character(len=*), intent(in) :: keys
    character(len=:), allocatable :: s
    s = blame(ck%reg, keys, ck%c%file)
  end function from

  !> '&particles key(k) = value'
  function item(key, k, x) result(s)
    character(len=*), intent(in) :: key
    integer, intent(in) :: k
    real(wp), intent(in) :: x
    character(len=:), allocatable :: s
    s = '&particles '//key//'('//itoa(k)//') = '//fmt_num(x)
  end function item

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
  function pair_text(ck, key, k, m) result(s)
    type(check_t), intent(in) :: ck
    character(len=*), intent(in) :: key
    integer, intent(in) :: k, m
    character(len=:), allocatable :: s
    real(wp) :: a, b
    associate (p => ck%c%particles)
      select case (key)
      case ('x')
        a = p%x(k); b = p%x(m)
      case ('y')
        a = p%y(k); b = p%y(m)
      case default
        a = p%diameter(k); b = p%diameter(m)
      end select
    end associate
    s = key//'('//itoa(k)//') = '//fmt_num(a)//' and '//key//'('//itoa(m)//') = '//fmt_num(b)
  end function pair_text

end module dkt_config_checks

!> Run diagnostics and guards: a non-finite population or a Mach number above the limit stops
!> the run (collectively, its output written and closed) with what, where, when, and what to
!> change; so does a particle faster than run.particle_speed_limit spacings per step (or with a
!> non-finite velocity). For a pair of particles (docs/model.md §6): the
!> gaps D_x, D_y, D_r, the particle Reynolds number Re_a and drag coefficient C_d (E12), and
!> the kissing episodes with the DKT pattern they make.
!>
!> A kissing episode starts when the surface gap D_r falls to `enter` or below and ends when it
!> grows above `release` (> enter): the hysteresis keeps a gap that hovers near the contact
!> range of E10 from counting as many episodes. The pattern is 'repeated' for two or more
!> episodes, 'once' for one, 'never' for none.
module dkt_diagnostics
  use ieee_arithmetic, only: ieee_is_finite, ieee_value, ieee_quiet_nan
  use mpi_f08, only: MPI_Allreduce, MPI_Bcast, MPI_IN_PLACE, MPI_MAX, MPI_MIN, MPI_INTEGER, &
                     MPI_CHARACTER
  use iso_fortran_env, only: int64
  use dkt_kinds, only: wp, mpi_wp, cs2
  use dkt_domain, only: domain_t
  use dkt_fields, only: node_moments, row_speed2
  use dkt_store, only: lattice_t, lattice_get_node, lattice_get_row
  implicit none
  private
  public :: guard_check, guard_particle_speed, guard_set_advice, SQ_UNDAMPED, pair_diag_t, &
            pair_diag_init, &
            pair_diag_update, pair_pattern, pair_gaps, drag_coefficient

  !> The kissing episodes of a pair, updated as the run goes.
  type :: pair_diag_t
    real(wp) :: enter = 0.0_wp           !! D_r at or below which an episode starts
    real(wp) :: release = 0.0_wp         !! D_r above which it ends
    logical :: in_episode = .false.      !! the last update was inside an episode
    integer :: n = 0                     !! episodes so far (the current one included)
    real(wp), allocatable :: t_start(:)  !! start time of each episode
    real(wp), allocatable :: t_end(:)    !! end time; the last update time while open
    real(wp), allocatable :: gap_min(:)  !! smallest D_r of each episode
  end type pair_diag_t

  !> MRT heat-flux rate below which the q moments count as almost undamped: the E3 rule gives
  !! less near tau = 1/2 (0.06 at tau = 0.512, 0.005 at 0.501). Measured: the Uhlmann DKT pair
  !! (input/uhlmann.nml, s_q = 0) blew up at tau = 0.512-0.53 at 20-40 spacings per diameter,
  !! and with s_q = 1.2 ran through (docs/stability.md)
  real(wp), parameter :: SQ_UNDAMPED = 0.25_wp

  !> how to make dx smaller in the running scene (lbm.dx, or lbm.cells_per_diameter when that
  !! sets dx), for the guards' advice
  character(len=:), allocatable, save :: dx_advice
  !> what the non-finite and Mach guards add for the running scene ('' or the s_q advice)
  character(len=:), allocatable, save :: extra_advice

contains

  !> Set how the guards' messages tell to make dx smaller (the scene's own knob), and, for
  !! moving particles on the MRT model with s_q below SQ_UNDAMPED, that the likely cause of a
  !! run-away flow is the undamped heat-flux moments and how to damp them.
  subroutine guard_set_advice(dx_knob, s_q, moving_mrt)
    character(len=*), intent(in) :: dx_knob
    real(wp), intent(in) :: s_q           !! the heat-flux rate in use
    logical, intent(in) :: moving_mrt     !! particles move and the collision is MRT
    character(len=16) :: rate
    dx_advice = dx_knob
    extra_advice = ''
    if (moving_mrt .and. s_q < SQ_UNDAMPED) then
      write (rate, '(f6.3)') s_q
      extra_advice = '. The heat-flux rate s_q = '//trim(adjustl(rate))//' is below '// &
                     'the measured stable range near tau = 1/2: set lbm.s_q = 1.2 first'
    end if
  end subroutine guard_set_advice

  !> Check every node of the slab for a non-finite value or |u|/c_s above mach_limit.
  !! Collective: every rank returns the largest Mach number over all ranks and the same
  !! `failure`, '' when all is well, else what, where, when and what to change at the first
  !! failing node of the lowest rank with the worst kind of failure (non-finite before Mach).
  !! The caller stops the run, so that all ranks write their output and close it together.
  subroutine guard_check(dom, f, force, mach_limit, step, t, dx, y_offset, mach_max, failure)
    type(domain_t), intent(in) :: dom
    type(lattice_t), intent(in) :: f      !! the populations, checked unshifted in 8 bytes
    real(wp), intent(in) :: force(2)      !! body force, lattice units
    real(wp), intent(in) :: mach_limit    !! largest allowed |u|/c_s
    integer, intent(in) :: step           !! time step
    real(wp), intent(in) :: t, dx         !! time (s) and lattice spacing (cm), for the message
    real(wp), intent(in) :: y_offset      !! cm, y of the lattice's lower end (a moving window)
    real(wp), intent(out) :: mach_max     !! largest |u|/c_s on any rank
    character(len=:), allocatable, intent(out) :: failure
    integer, parameter :: OK = 0, TOO_FAST = 1, NON_FINITE = 2
    real(wp) :: u2_max
    logical :: finite
    integer :: kind, worst, root
    character(len=1024) :: msg

    if (.not. allocated(dx_advice)) dx_advice = 'make lbm.dx smaller'
    if (.not. allocated(extra_advice)) extra_advice = ''
    kind = OK
    msg = ''
    ! the row pass decides for a healthy flow; only a slab it does not clear is scanned node by
    ! node below, for the first failing node and the message
    call guard_rows(dom, f, force, u2_max, finite)
    mach_max = sqrt(u2_max/cs2)
    if (.not. finite .or. mach_max > mach_limit) call guard_nodes()
    call MPI_Allreduce(MPI_IN_PLACE, mach_max, 1, mpi_wp, MPI_MAX, dom%comm)
    call MPI_Allreduce(kind, worst, 1, MPI_INTEGER, MPI_MAX, dom%comm)
    failure = ''
    if (worst == OK) return
    ! the lowest rank with the worst failure sends its message to all
    call MPI_Allreduce(merge(dom%rank, huge(0), kind == worst), root, 1, MPI_INTEGER, MPI_MIN, &
                       dom%comm)
    call MPI_Bcast(msg, len(msg), MPI_CHARACTER, root, dom%comm)
    failure = trim(msg)

  contains

    !> Every node in turn: the first non-finite node, else the first above the limit.
    subroutine guard_nodes()
      real(wp) :: rho, ux, uy, ma, fn(0:8)
      logical :: node_finite
      integer :: x, j

      mach_max = 0.0_wp
      scan: do j = 1, dom%nyl
        do x = 1, dom%nx
          fn = lattice_get_node(f, x, j)
          ! the moments only of finite populations (an infinity would trap in the checked build)
          node_finite = all(ieee_is_finite(fn))
          if (node_finite) then
            call node_moments(fn, force, rho, ux, uy)
            node_finite = ieee_is_finite(ux) .and. ieee_is_finite(uy)
          end if
          if (.not. node_finite) then
            write (msg, '(a,i0,a,es12.4e3,a,2(i0,a),2(es12.4e3,a),a)') &
              'non-finite value at step ', step, ' (t = ', t, ' s), node (', x, ', ', &
              dom%y0 + j, ') at (', (x - 0.5_wp)*dx, ', ', &
              y_offset + (dom%y0 + j - 0.5_wp)*dx, ') cm. The run became unstable: ', &
              'increase lbm.tau, '//dx_advice//' for a smaller dt, or lower the velocity scale'// &
              extra_advice
            kind = NON_FINITE
            exit scan
          end if
          ma = sqrt((ux*ux + uy*uy)/cs2)
          if (ma > mach_limit .and. kind == OK) then
            write (msg, '(a,es12.4e3,a,es12.4e3,a,i0,a,es12.4e3,a,2(i0,a),2(es12.4e3,a),a)') &
              'Mach number ', ma, ' above run.mach_limit = ', mach_limit, ' at step ', step, &
              ' (t = ', t, ' s), node (', x, ', ', dom%y0 + j, ') at (', (x - 0.5_wp)*dx, ', ', &
              y_offset + (dom%y0 + j - 0.5_wp)*dx, ') cm. Lower lbm.tau or '//dx_advice//' ', &
              '(both shrink dt and the lattice velocity), or lower the flow speed'//extra_advice
            kind = TOO_FAST
          end if
          mach_max = max(mach_max, ma)
        end do
      end do scan
    end subroutine guard_nodes
  end subroutine guard_check

  !> The first pass of guard_check, a row at a time along x (it vectorises): the largest
  !! u_x² + u_y² of the slab and whether every node's density and u² are finite. Each node's
  !! values are those of node_moments (dkt_fields row_speed2), and the square root is monotonic,
  !! so sqrt(u2_max/c_s²) is the largest Mach number of the node-by-node scan, bit for bit. Where
  !! `finite` holds (every population, density and u² finite; a finite u² has finite
  !! components), the scan finds no non-finite value either.
  subroutine guard_rows(dom, f, force, u2_max, finite)
    type(domain_t), intent(in) :: dom
    type(lattice_t), intent(in) :: f
    real(wp), intent(in) :: force(2)
    real(wp), intent(out) :: u2_max
    logical, intent(out) :: finite
    real(wp), allocatable :: fr(:, :), rho(:), u2(:)
    integer :: j, nx
    nx = dom%nx
    allocate (fr(nx, 0:8), rho(nx), u2(nx))
    u2_max = 0.0_wp
    finite = .true.
    do j = 1, dom%nyl
      call lattice_get_row(f, j, nx, fr)
      ! the populations first, with a test that raises no exception: no arithmetic on a NaN or
      ! an infinity (the checked build traps an invalid operation; the node scan then reports it)
      finite = all_finite(fr, nx*9)
      if (.not. finite) return
      call row_speed2(fr, nx, force, rho, u2)
      finite = all_finite(rho, nx) .and. all_finite(u2, nx)
      if (.not. finite) return
      u2_max = max(u2_max, maxval(u2))
    end do
  end subroutine guard_rows

  !> Whether the first n values of a are finite, read from their exponent bits (all ones for an
  !! infinity or a NaN): no floating-point operation touches a NaN (the checked build traps an
  !! invalid one), and the reduction has no early exit, so it vectorises. It decides as
  !! ieee_is_finite does, value by value; the guard pass, which reads every node every
  !! run.guard_every steps, took four times a flow step with the element-wise test.
  pure logical function all_finite(a, n)
    integer, intent(in) :: n
    real(wp), intent(in) :: a(n)
    integer(int64), parameter :: EXPONENT_BITS = int(z'7FF0000000000000', int64)
    integer(int64) :: largest
    integer :: k
    largest = 0
    do k = 1, n
      largest = max(largest, iand(transfer(a(k), 0_int64), EXPONENT_BITS))
    end do
    all_finite = largest < EXPONENT_BITS
  end function all_finite

  !> The particle guard: '' when every particle moves at most `limit` lattice spacings per
  !! step, else what, where, when and what to change for the first that does not (a NaN or
  !! infinite velocity fails too). A particle that fast crosses a node in under 1/limit steps:
  !! its boundary links (E6) and the nodes it uncovers lag behind it, and the force on it is
  !! no longer the fluid's. Every rank holds the same particle states (particles_move sends
  !! them to all), so every rank returns the same failure without communication.
  function guard_particle_speed(u, v, x, y, limit, step, t, dx, y_offset, id) result(failure)
    real(wp), intent(in) :: u(:), v(:)    !! particle velocities, lattice units
    real(wp), intent(in) :: x(:), y(:)    !! particle centres, lattice units
    real(wp), intent(in) :: limit         !! run.particle_speed_limit
    integer, intent(in) :: step           !! time step
    real(wp), intent(in) :: t, dx         !! time (s) and lattice spacing (cm), for the message
    real(wp), intent(in) :: y_offset      !! cm, y of the lattice's lower end (a moving window)
    integer, intent(in), optional :: id   !! the number of the first particle given (default 1)
    character(len=:), allocatable :: failure
    character(len=512) :: msg
    real(wp) :: speed
    integer :: k, first
    if (.not. allocated(dx_advice)) dx_advice = 'make lbm.dx smaller'
    failure = ''
    first = 1
    if (present(id)) first = id
    do k = 1, size(u)
      speed = hypot(u(k), v(k))
      ! a NaN or infinite speed fails as well (tested first: an ordered comparison with NaN
      ! raises the invalid-operation exception the checked build traps)
      if (ieee_is_finite(speed)) then
        if (speed <= limit) cycle
      end if
      write (msg, '(a,i0,a,es12.4e3,a,es12.4e3,a,i0,a,es12.4e3,a,2(es12.4e3,a),a)') &
        'particle ', first + k - 1, ' moves ', speed, ' lattice spacings per step, above '// &
        'run.particle_speed_limit = ', limit, ', at step ', step, ' (t = ', t, &
        ' s), centre at (', x(k)*dx, ', ', y_offset + y(k)*dx, ') cm: its boundary links '// &
        'lag behind it. Lower lbm.tau or '//dx_advice//' (both shrink dt/dx), or slow the '// &
        'particle (density ratio, gravity, initial u, v)'
      failure = trim(msg)
      return
    end do
  end function guard_particle_speed

  !> Start with no episode; the thresholds are in the units of the D_r given to the updates.
  subroutine pair_diag_init(d, enter, release)
    type(pair_diag_t), intent(out) :: d
    real(wp), intent(in) :: enter, release
    d%enter = enter
    d%release = release
    allocate (d%t_start(0), d%t_end(0), d%gap_min(0))
  end subroutine pair_diag_init

  !> One sample (time t, surface gap dr) of the pair, in time order.
  pure subroutine pair_diag_update(d, t, dr)
    type(pair_diag_t), intent(inout) :: d
    real(wp), intent(in) :: t, dr
    if (d%in_episode) then
      if (dr > d%release) then
        d%in_episode = .false.
      else
        d%t_end(d%n) = t
        d%gap_min(d%n) = min(d%gap_min(d%n), dr)
      end if
    else if (dr <= d%enter) then
      d%in_episode = .true.
      d%n = d%n + 1
      d%t_start = [d%t_start, t]
      d%t_end = [d%t_end, t]
      d%gap_min = [d%gap_min, dr]
    end if
  end subroutine pair_diag_update

  !> 'repeated' (two or more episodes), 'once' (one) or 'never' (none).
  pure function pair_pattern(d) result(name)
    type(pair_diag_t), intent(in) :: d
    character(len=:), allocatable :: name
    select case (d%n)
    case (0); name = 'never'
    case (1); name = 'once'
    case default; name = 'repeated'
    end select
  end function pair_pattern

  !> docs/model.md §6: D_x = x_1 - x_2, D_y = y_1 - y_2, D_r = |X_1 - X_2| - (r_1 + r_2).
  pure subroutine pair_gaps(x1, y1, r1, x2, y2, r2, gx, gy, gr)
    real(wp), intent(in) :: x1, y1, r1, x2, y2, r2
    real(wp), intent(out) :: gx, gy, gr
    gx = x1 - x2
    gy = y1 - y2
    gr = hypot(gx, gy) - (r1 + r2)
  end subroutine pair_gaps

  !> E12: C_d = F_d / (rho_f U_p^2 D_p / 2), F_d the streamwise (y) hydrodynamic force per
  !! unit depth and U_p the particle speed; NaN for a particle at rest.
  elemental real(wp) function drag_coefficient(fy, u, v, rho_f, d) result(cd)
    real(wp), intent(in) :: fy, u, v, rho_f, d
    real(wp) :: q
    q = 0.5_wp*rho_f*(u*u + v*v)*d
    if (q > 0.0_wp) then
      cd = fy/q
    else
      cd = ieee_value(cd, ieee_quiet_nan)
    end if
  end function drag_coefficient

end module dkt_diagnostics

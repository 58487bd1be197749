!> Channel boundaries (docs/model.md §2): side walls and closed ends by half-way bounce-back,
!> periodic sides and ends, and open ends by non-equilibrium extrapolation (E5).
!>
!> Bounce-back and periodicity are applied as ghost values before the pull sweep: the ghost
!> that node x pulls population i from holds f*_opp(i)(x) (wall) or the periodic image.
!> Open ends are applied after the sweep to the end rows, on post-collision populations:
!> setting f*(x_b) = f^eq(rho_b, u_b) + [f*(x_n) - f^eq(x_n)] is the same as applying E5
!> before the collision and colliding with the same rates.
!>
!> Ghost values are copies between populations of equal weight (a bounce-back pair, a
!> periodic image, the same population): they move the stored values as they are, in either
!> storage (dkt_store). E5 is computed from the unshifted populations in 8 bytes.
module dkt_boundary
  use dkt_kinds, only: wp, pi
  use dkt_choices, only: END_WALL, END_PERIODIC, END_VELOCITY, END_OUTFLOW
  use dkt_errors, only: internal_error
  use dkt_text, only: itoa
  use dkt_lattice, only: ex, ey, opp, equilibrium
  use dkt_domain, only: domain_t
  use dkt_store, only: lattice_t, lattice_get_node, lattice_set_node
  implicit none
  private
  public :: boundary_t, boundary_init, fill_local_ghosts, fill_halo_ghosts, apply_open_ends, &
            END_WALL, END_PERIODIC, END_VELOCITY, END_OUTFLOW, inlet_profile

  integer, parameter :: plus_x(3) = [1, 5, 8], minus_x(3) = [3, 6, 7]
  integer, parameter :: plus_y(3) = [2, 5, 6], minus_y(3) = [4, 7, 8]

  type :: boundary_t
    logical :: periodic_x = .false.  !! sides periodic instead of walls
    integer :: lower = END_WALL      !! kind of the y = 0 end
    integer :: upper = END_WALL      !! kind of the y = H end
    real(wp) :: u_in = 0.0_wp        !! inlet y-velocity (centreline if parabolic), lattice units
    logical :: parabolic = .true.    !! inlet profile
    real(wp) :: ramp_steps = 0.0_wp  !! inlet ramp-up duration in steps
  end type boundary_t

contains

  subroutine boundary_init(bc, periodic_x, lower, upper, u_in, parabolic, ramp_steps)
    type(boundary_t), intent(out) :: bc
    logical, intent(in) :: periodic_x, parabolic
    integer, intent(in) :: lower, upper
    real(wp), intent(in) :: u_in, ramp_steps
    ! an end code outside END_* would silently be no end at all
    if (any([lower, upper] < END_WALL .or. [lower, upper] > END_OUTFLOW)) &
      call internal_error('boundary_init: end codes '//itoa(lower)//', '//itoa(upper)// &
                          ' are not END_WALL .. END_OUTFLOW')
    bc%periodic_x = periodic_x
    bc%lower = lower
    bc%upper = upper
    bc%u_in = u_in
    bc%parabolic = parabolic
    bc%ramp_steps = ramp_steps
  end subroutine boundary_init

  !> Inlet y-velocity at column x (cell centre (x - 1/2) dx) and time step n: a parabola with
  !! zero at the side walls, or uniform; ramped up as (1 - cos(pi n/N))/2 over N steps.
  pure real(wp) function inlet_profile(bc, nx, x, n) result(u)
    type(boundary_t), intent(in) :: bc
    integer, intent(in) :: nx, x, n
    real(wp) :: xi
    u = bc%u_in
    if (bc%parabolic) then
      xi = (real(x, wp) - 0.5_wp)/real(nx, wp)
      u = u*4.0_wp*xi*(1.0_wp - xi)
    end if
    if (real(n, wp) < bc%ramp_steps) u = u*0.5_wp*(1.0_wp - cos(pi*real(n, wp)/bc%ramp_steps))
  end function inlet_profile

  !> Ghosts that need only this slab's own rows: side walls on every row, periodic sides on
  !! rows 1..nyl, and the halo row at a physical end of the channel.
  subroutine fill_local_ghosts(bc, dom, f)
    type(boundary_t), intent(in) :: bc
    type(domain_t), intent(in) :: dom
    type(lattice_t), intent(inout) :: f
    integer :: k, i, nx, nyl
    nx = dom%nx
    nyl = dom%nyl
    if (bc%periodic_x) then
      call periodic_columns(f, nx, 1, nyl)
    else
      ! the ghost at (0, j) is pulled by (1, j + ey): it holds f*_opp there (bounce-back)
      do k = 1, 3
        i = plus_x(k)
        if (f%half) then
          f%h(0, 1 - ey(i):nyl - ey(i), i) = f%h(1, 1:nyl, opp(i))
        else if (f%single) then
          f%s(0, 1 - ey(i):nyl - ey(i), i) = f%s(1, 1:nyl, opp(i))
        else
          f%d(0, 1 - ey(i):nyl - ey(i), i) = f%d(1, 1:nyl, opp(i))
        end if
        i = minus_x(k)
        if (f%half) then
          f%h(nx + 1, 1 - ey(i):nyl - ey(i), i) = f%h(nx, 1:nyl, opp(i))
        else if (f%single) then
          f%s(nx + 1, 1 - ey(i):nyl - ey(i), i) = f%s(nx, 1:nyl, opp(i))
        else
          f%d(nx + 1, 1 - ey(i):nyl - ey(i), i) = f%d(nx, 1:nyl, opp(i))
        end if
      end do
    end if
    if (dom%has_lower_end) call end_row(bc, bc%lower, f, nx, 0, 1, plus_y)
    if (dom%has_upper_end) call end_row(bc, bc%upper, f, nx, nyl + 1, nyl, minus_y)
  end subroutine fill_local_ghosts

  !> Ghosts that need the halo rows just received: the periodic-side corners of halo rows that
  !! hold neighbour data (or the copy at an open end); a wall end set its corners itself.
  subroutine fill_halo_ghosts(bc, dom, f)
    type(boundary_t), intent(in) :: bc
    type(domain_t), intent(in) :: dom
    type(lattice_t), intent(inout) :: f
    if (.not. bc%periodic_x) return
    if (.not. (dom%has_lower_end .and. bc%lower == END_WALL)) &
      call periodic_columns(f, dom%nx, 0, 0)
    if (.not. (dom%has_upper_end .and. bc%upper == END_WALL)) &
      call periodic_columns(f, dom%nx, dom%nyl + 1, dom%nyl + 1)
  end subroutine fill_halo_ghosts

  !> Periodic images in the ghost columns for rows j1..j2.
  subroutine periodic_columns(f, nx, j1, j2)
    type(lattice_t), intent(inout) :: f
    integer, intent(in) :: nx, j1, j2
    integer :: k
    do k = 1, 3
      if (f%half) then
        f%h(0, j1:j2, plus_x(k)) = f%h(nx, j1:j2, plus_x(k))
        f%h(nx + 1, j1:j2, minus_x(k)) = f%h(1, j1:j2, minus_x(k))
      else if (f%single) then
        f%s(0, j1:j2, plus_x(k)) = f%s(nx, j1:j2, plus_x(k))
        f%s(nx + 1, j1:j2, minus_x(k)) = f%s(1, j1:j2, minus_x(k))
      else
        f%d(0, j1:j2, plus_x(k)) = f%d(nx, j1:j2, plus_x(k))
        f%d(nx + 1, j1:j2, minus_x(k)) = f%d(1, j1:j2, minus_x(k))
      end if
    end do
  end subroutine periodic_columns

  !> Halo row jg at an end of the channel, next to the end row jb; pops are the populations
  !! that row jb pulls from jg. A wall bounces back (x' is pulled by x = x' + ex, wrapped when
  !! the sides are periodic); an open end copies the end row, which E5 then overwrites.
  subroutine end_row(bc, kind, f, nx, jg, jb, pops)
    type(boundary_t), intent(in) :: bc
    integer, intent(in) :: kind, nx, jg, jb, pops(3)
    type(lattice_t), intent(inout) :: f
    integer :: k, i, xg, x
    do k = 1, 3
      i = pops(k)
      if (kind == END_WALL) then
        do xg = 0, nx + 1
          x = xg + ex(i)
          if (bc%periodic_x) x = modulo(x - 1, nx) + 1
          if (x < 1 .or. x > nx) cycle
          if (f%half) then
            f%h(xg, jg, i) = f%h(x, jb, opp(i))
          else if (f%single) then
            f%s(xg, jg, i) = f%s(x, jb, opp(i))
          else
            f%d(xg, jg, i) = f%d(x, jb, opp(i))
          end if
        end do
      else if (f%half) then
        f%h(1:nx, jg, i) = f%h(1:nx, jb, i)
      else if (f%single) then
        f%s(1:nx, jg, i) = f%s(1:nx, jb, i)
      else
        f%d(1:nx, jg, i) = f%d(1:nx, jb, i)
      end if
    end do
  end subroutine end_row

  !> E5 on the end rows of the new post-collision lattice at time step n.
  subroutine apply_open_ends(bc, dom, f, n)
    type(boundary_t), intent(in) :: bc
    type(domain_t), intent(in) :: dom
    type(lattice_t), intent(inout) :: f
    integer, intent(in) :: n
    if (dom%has_lower_end .and. bc%lower >= END_VELOCITY) &
      call extrapolate_row(bc, bc%lower, f, dom%nx, 1, 2, n)
    if (dom%has_upper_end .and. bc%upper >= END_VELOCITY) &
      call extrapolate_row(bc, bc%upper, f, dom%nx, dom%nyl, dom%nyl - 1, n)
  end subroutine apply_open_ends

  !> E5 (Guo, Zheng & Shi 2002): f(x_b) = f^eq(rho_b, u_b) + [f(x_n) - f^eq(rho_n, u_n)].
  !! A velocity end takes u_b from the inlet and rho_b = rho_n; an outflow takes u_b = u_n
  !! (zero normal gradient) and the reference density 1.
  subroutine extrapolate_row(bc, kind, f, nx, jb, jn, n)
    type(boundary_t), intent(in) :: bc
    integer, intent(in) :: kind, nx, jb, jn, n
    type(lattice_t), intent(inout) :: f
    real(wp) :: fn(0:8), rho, ux, uy
    integer :: x
    do x = 1, nx
      fn = lattice_get_node(f, x, jn)
      rho = sum(fn)
      ux = sum(ex*fn)/rho
      uy = sum(ey*fn)/rho
      fn = fn - equilibrium(rho, ux, uy)
      if (kind == END_VELOCITY) then
        call lattice_set_node(f, x, jb, equilibrium(rho, 0.0_wp, inlet_profile(bc, nx, x, n)) + fn)
      else
        call lattice_set_node(f, x, jb, equilibrium(1.0_wp, ux, uy) + fn)
      end if
    end do
  end subroutine extrapolate_row

end module dkt_boundary

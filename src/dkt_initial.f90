!> The fluid at t = 0 (&initial, docs/model.md §7): the equilibrium of the initial flow at every
!> node of a slab, at rest or a Taylor-Green vortex, with a uniform pressure or the hydrostatic
!> pressure that holds up the free particles' weight less buoyancy. Lattice units.
module dkt_initial
  use dkt_kinds, only: wp, pi, cs2
  use dkt_config, only: config_t, lattice_params_t
  use dkt_choices, only: FLOW_REST, FLOW_TAYLOR_GREEN, PRESSURE_HYDROSTATIC, MOTION_FREE
  use dkt_domain, only: domain_t
  use dkt_lattice, only: equilibrium
  use dkt_store, only: lattice_t, lattice_set_node
  use dkt_errors, only: internal_error
  use dkt_text, only: itoa
  implicit none
  private
  public :: initial_state

contains

  !> Initial populations of the slab dom: the equilibrium of the initial flow (the post-collision
  !! state at t = 0), at density 1 + (p + p_w(y))/c_s^2, p the flow's own pressure and p_w the
  !! hydrostatic weight (initial.pressure = 'hydrostatic', less its mean over the channel's rows
  !! so that the fluid's mean density stays rho_f, the density of E9's buoyancy and E7's rest
  !! state), 0 otherwise.
  subroutine initial_state(cfg, lp, dom, f)
    type(config_t), intent(in) :: cfg
    type(lattice_params_t), intent(in) :: lp
    type(domain_t), intent(in) :: dom
    type(lattice_t), intent(inout) :: f
    integer :: x, j, jg
    real(wp) :: kx, ky, u0, xc, yc, ux, uy, p, mean
    real(wp), allocatable :: rows(:), weight(:)
    allocate (weight(dom%nyl))
    weight = 0.0_wp
    if (cfg%initial%pressure_kind == PRESSURE_HYDROSTATIC) then
      ! every row of the channel, summed in ascending order on every rank: the same bits on any
      ! split; the slab takes its own rows of them
      allocate (rows(dom%ny))
      mean = 0.0_wp
      do jg = 1, dom%ny
        rows(jg) = weight_above(cfg, lp, real(jg, wp) - 0.5_wp)
        mean = mean + rows(jg)
      end do
      mean = mean/real(dom%ny, wp)
      weight = rows(dom%y0 + 1:dom%y0 + dom%nyl) - mean
    end if
    ! (lattice_allocate touched every entry, ghosts and padding included: no garbage is read)
    select case (cfg%initial%flow_kind)
    case (FLOW_TAYLOR_GREEN)
      ! u = U(-cos kx sin ky, sin kx cos ky), p = -U^2/4 (cos 2kx + cos 2ky) (lattice units)
      kx = 2.0_wp*pi/real(lp%nx, wp)
      ky = 2.0_wp*pi/real(dom%ny, wp)
      u0 = lp%u_init_lb
      do j = 1, dom%nyl
        jg = dom%y0 + j
        do x = 1, lp%nx
          xc = real(x, wp) - 0.5_wp
          yc = real(jg, wp) - 0.5_wp
          ux = -u0*cos(kx*xc)*sin(ky*yc)
          uy = u0*sin(kx*xc)*cos(ky*yc)
          p = -0.25_wp*u0*u0*(cos(2.0_wp*kx*xc) + cos(2.0_wp*ky*yc))
          call lattice_set_node(f, x, j, equilibrium(1.0_wp + (p + weight(j))/cs2, ux, uy))
        end do
      end do
    case (FLOW_REST)
      do j = 1, dom%nyl
        do x = 1, lp%nx
          call lattice_set_node(f, x, j, equilibrium(1.0_wp + weight(j)/cs2, 0.0_wp, 0.0_wp))
        end do
      end do
    case default
      call internal_error('initial_state: initial.flow code '//itoa(cfg%initial%flow_kind))
    end select
  end subroutine initial_state

  !> The weight less buoyancy of the free particles above the height y, per unit width (lattice
  !! units, y from the lower end at t = 0): g sum_k (rho_k/rho_f - 1) A_k(y), A_k(y) the part of
  !! disk k's area above y. A fluid at rest under this pressure holds the particles' excess
  !! weight up as a settling suspension's fluid does, so that they do not fall freely while a
  !! pressure wave builds it (docs/model.md §7). From the whole scene: the same on every rank.
  pure real(wp) function weight_above(cfg, lp, y) result(w)
    type(config_t), intent(in) :: cfg
    type(lattice_params_t), intent(in) :: lp
    real(wp), intent(in) :: y
    integer :: k
    real(wp) :: r, d, area
    w = 0.0_wp
    associate (p => lp%particles)
      do k = 1, size(p%x)
        if (cfg%particles%motion_kind(k) /= MOTION_FREE) cycle
        r = p%r(k)
        d = y - p%y(k)
        if (d >= r) then
          area = 0.0_wp
        else if (d <= -r) then
          area = pi*r*r
        else
          ! the circular segment above the chord at the distance d from the centre
          area = r*r*acos(d/r) - d*sqrt(r*r - d*d)
        end if
        w = w + (p%density(k) - 1.0_wp)*area
      end do
      w = w*p%gravity/real(lp%nx, wp)
    end associate
  end function weight_above

end module dkt_initial

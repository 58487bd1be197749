!> The motion of the particles (docs/model.md §3–4): Newton–Euler (E8) with gravity and buoyancy
!> (E9) and the short-range forces of dkt_collisions (E10–E11), in sub-steps; each owner moves its
!> own particles, the messages of dkt_particles bring the new states to the slabs that hold
!> them (the caller then refills the nodes the disks uncovered: dkt_links).
module dkt_particle_motion
  use, intrinsic :: ieee_arithmetic, only: ieee_is_finite
  use dkt_kinds, only: wp, pi
  use dkt_choices, only: MOTION_FREE, MOTION_FIXED, MOTION_PRESCRIBED
  use dkt_domain, only: domain_t
  use dkt_collisions, only: collision_force_on, collision_partners
  use dkt_errors, only: internal_error
  use dkt_text, only: itoa
  use dkt_cells, only: cells_build, cells_near, cells_candidates
  use dkt_particles, only: particles_t, particles_exchange
  use dkt_particle_state, only: state_copy_first
  use dkt_lubrication, only: lubrication_add_pair, lubrication_add_walls
  implicit none
  private
  public :: particles_move

  !> The farthest a particle's centre moves from its start in a step before its contacts take
  !! every candidate in place of the partners (collision_partners), with the same bits: about
  !! the most it moves at the largest allowed speed (run.particle_speed_limit <= 1 spacing per
  !! step), so that hardly a step takes them.
  real(wp), parameter :: DRIFT = 1.0_wp

contains

  !> E8–E11: each owner advances its particles by one fluid step (in sub-steps for the contact
  !! forces, the other particles held at their start-of-step positions: a slab holds every
  !! partner of its own particles), prescribed ones by their given velocity. The owners then
  !! send the new states to the neighbouring slabs (particles_exchange): a particle whose centre
  !! crossed into another slab is owned there from now on. The caller then refills the nodes
  !! the particles uncovered (dkt_links' links_refill). When every particle is fixed (moving
  !! false) the owners compute the contact forces and nothing is sent: no node is uncovered.
  subroutine particles_move(ps, dom, end_walls, moving)
    type(particles_t), intent(inout) :: ps
    type(domain_t), intent(in) :: dom
    logical, intent(in) :: end_walls(2) !! the lower, the upper end is a wall (E11 against it)
    logical, intent(in) :: moving    !! some particle is free or prescribed
    real(wp) :: h, ax, ay, gy, xs(ps%n), ys(ps%n), rs(ps%n), xk, yk
    real(wp), allocatable :: us(:), vs(:)
    real(wp) :: width, height, reach
    integer :: k, s, m, np
    integer, allocatable :: near(:), part(:)
    logical :: walls(4), alone, sorted
    h = 1.0_wp/ps%substeps
    width = real(dom%nx, wp)
    height = real(dom%ny, wp)
    ! the start-of-step centres, which the contacts take; the particle being moved puts its
    ! present centre in its own place during its sub-steps
    xs = ps%p%x(1:ps%n)
    ys = ps%p%y(1:ps%n)
    rs = ps%p%r(1:ps%n)
    ! the start-of-step velocities, which the lubrication films (E13) take for the partners
    if (ps%lub%on) then
      us = ps%p%u(1:ps%n)
      vs = ps%p%v(1:ps%n)
    end if
    ! contact partners (E10) and films (E13) lie within r_k + rmax + partner_range of a centre
    call cells_build(ps%cells, xs, ys, 2.0_wp*ps%rmax + ps%partner_range)
    if (moving) then
      call state_copy_first(ps%old, ps%p, ps%n)
      ps%nold = ps%n
    end if
    do k = 1, ps%n
      if (ps%home(k) /= dom%rank) cycle
      xk = xs(k)
      yk = ys(k)
      ! the candidates once for all sub-steps: within the contact reach of the centre at the
      ! start, plus the most it moves in a step (run.particle_speed_limit <= 1). A candidate
      ! beyond the reach adds an exact zero (E10), so the sums are those of a query per sub-step
      reach = rs(k) + ps%rmax + ps%partner_range + 2.0_wp
      call cells_candidates(ps%cells, xk, yk, reach, near, m)
      ! of them, those that can push k while it stays within DRIFT of its start, and the walls
      ! that can: a sub-step there takes these alone (the others add exact zeros), and adds
      ! nothing when there are none; one beyond takes every candidate, ascending, and every wall
      call collision_partners(k, xs, ys, rs, width, height, end_walls, ps%partner_range, &
                              DRIFT, near(1:m), part, np, walls)
      alone = np == 0 .and. .not. any(walls)
      sorted = .false.
      associate (p => ps%p)
        do s = 1, ps%substeps
          xs(k) = p%x(k)
          ys(k) = p%y(k)
          if (.not. within_drift(xs(k) - xk, ys(k) - yk)) then
            if (.not. sorted) call cells_near(ps%cells, xk, yk, reach, near, m)
            sorted = .true.
            call collision_force_on(k, xs, ys, rs, width, height, end_walls, ps%stiffness, &
                                    ps%stiffness_overlap, ps%range, p%cx(k), p%cy(k), near(1:m))
          else if (alone) then
            ! (the sum of collision_force_on over no terms)
            p%cx(k) = 0.0_wp
            p%cy(k) = 0.0_wp
          else
            call collision_force_on(k, xs, ys, rs, width, height, end_walls, ps%stiffness, &
                                    ps%stiffness_overlap, ps%range, p%cx(k), p%cy(k), &
                                    part(1:np), walls)
          end if
          select case (p%motion(k))
          case (MOTION_FREE)
            ! E9: weight minus buoyancy, (rho_p - rho_f) pi r^2 g along -y
            gy = -(p%density_ratio(k) - 1.0_wp)*pi*p%r(k)**2*ps%gravity
            ! the hydrodynamic part: this step's force, or its mean with the last (E8)
            ax = (ps%drive_x(k) + p%cx(k))/p%mass(k)
            ay = (ps%drive_y(k) + p%cy(k) + gy)/p%mass(k)
            ! E13, implicit in the disk's own velocity: (M + h C) U_new = M U + h (F + C U_b)
            if (ps%lub%on .and. (sorted .or. .not. alone)) then
              if (sorted) then
                call films(k, near(1:m), [.true., .true., end_walls], ax, ay)
              else
                call films(k, part(1:np), walls, ax, ay)
              end if
            end if
            ! E8: X += U h + a h^2 / 2, U += a h, Omega += T/I h
            p%x(k) = p%x(k) + p%u(k)*h + 0.5_wp*ax*h*h
            p%y(k) = p%y(k) + p%v(k)*h + 0.5_wp*ay*h*h
            p%u(k) = p%u(k) + ax*h
            p%v(k) = p%v(k) + ay*h
            p%omega(k) = p%omega(k) + ps%drive_torque(k)/p%inertia(k)*h
          case (MOTION_PRESCRIBED)
            p%x(k) = p%x(k) + p%u(k)*h
            p%y(k) = p%y(k) + p%v(k)*h
          case (MOTION_FIXED)
          case default
            call internal_error('particles_move: motion code '//itoa(p%motion(k)))
          end select
        end do
        xs(k) = xk
        ys(k) = yk
      end associate
    end do
    if (.not. moving) return
    call particles_exchange(ps, dom)
  contains
    !> Turn the explicit acceleration (ax, ay) of free particle k into that of E8 with the
    !! lubrication films of the partners `with` and the walls taken: with a = sum C n n^T and
    !! b = sum C (U_b . n) n, (M I + h a) U_new = M U + h (M acc + b), acc = (U_new - U)/h.
    subroutine films(k, with, walls_taken, ax, ay)
      integer, intent(in) :: k, with(:)
      logical, intent(in) :: walls_taken(4)
      real(wp), intent(inout) :: ax, ay
      real(wp) :: a(3), b(2), mass, rx, ry, det, wx, wy
      integer :: j, l
      a = 0.0_wp
      b = 0.0_wp
      do l = 1, size(with)
        j = with(l)
        if (j == k) cycle
        call lubrication_add_pair(ps%lub, xs(k), ys(k), rs(k), xs(j), ys(j), rs(j), us(j), &
                                  vs(j), a, b)
      end do
      call lubrication_add_walls(ps%lub, xs(k), ys(k), rs(k), width, height, walls_taken, a, b)
      if (all(a == 0.0_wp)) return
      mass = ps%p%mass(k)
      ! the right-hand side M U + h (M acc + b), and the matrix M I + h a
      rx = mass*ps%p%u(k) + h*(mass*ax + b(1))
      ry = mass*ps%p%v(k) + h*(mass*ay + b(2))
      a = h*a
      a(1) = a(1) + mass
      a(3) = a(3) + mass
      det = a(1)*a(3) - a(2)*a(2)
      wx = (a(3)*rx - a(2)*ry)/det
      wy = (a(1)*ry - a(2)*rx)/det
      ax = (wx - ps%p%u(k))/h
      ay = (wy - ps%p%v(k))/h
    end subroutine films
  end subroutine particles_move

  !> Whether a centre moved by (dx, dy) from its start of step is within DRIFT of it (false for
  !! a centre that is not finite).
  pure logical function within_drift(dx, dy)
    real(wp), intent(in) :: dx, dy
    within_drift = ieee_is_finite(dx) .and. ieee_is_finite(dy)
    if (within_drift) within_drift = dx**2 + dy**2 <= DRIFT**2
  end function within_drift

end module dkt_particle_motion

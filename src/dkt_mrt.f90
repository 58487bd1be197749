!> The collision operator and the fused pull-stream + collide sweep (docs/model.md E1–E4).
!>
!> Arrays hold post-collision populations f*(x, t). One sweep pulls f*(x - e_i, t) into each
!> node (streaming), collides there and stores f*(x, t + 1) in the other lattice. The MRT
!> transform is written out (orthogonal rows, M^-1 = M^T D^-1) rather than a 9x9 product, and
!> the inner loop runs along x so that it vectorises. A uniform body force enters through
!> Guo's forcing term in moment space; a scene without one does not compute it.
module dkt_mrt
  use dkt_kinds, only: wp
  implicit none
  private
  public :: collision_t, collision_init, stream_collide, collision_describe, e3_heat_flux_rate

  !> Relaxation rates (docs/model.md E3) and the optional body force, in lattice units.
  type, public :: collision_t
    logical :: bgk = .false.        !! E4: single rate 1/tau, equilibrium in velocity space
    real(wp) :: s_nu = 1.0_wp       !! viscous rate 1/tau (p_xx, p_xy)
    real(wp) :: s_e = 1.0_wp        !! energy rate
    real(wp) :: s_eps = 1.0_wp      !! energy-square rate
    real(wp) :: s_q = 1.0_wp        !! heat-flux rate (q_x, q_y)
    logical :: forced = .false.     !! whether a body force acts on the fluid
    real(wp) :: force(2) = 0.0_wp   !! body force per unit volume, lattice units
  end type collision_t

contains

  !> E3: the heat-flux rate s_q = 8(2 - s_nu)/(8 - s_nu) that places a bounce-back wall exactly
  !! half-way between nodes, whatever the viscosity.
  pure real(wp) function e3_heat_flux_rate(s_nu) result(s_q)
    real(wp), intent(in) :: s_nu !! viscous rate 1/tau
    s_q = 8.0_wp*(2.0_wp - s_nu)/(8.0_wp - s_nu)
  end function e3_heat_flux_rate

  !> Set the collision from the nine rates in moment order (rho, e, eps, jx, qx, jy, qy, pxx,
  !! pxy) and the model switch; with bgk (E4) only the viscous rate s(7) = 1/tau is used.
  subroutine collision_init(coll, s, bgk, force)
    type(collision_t), intent(out) :: coll
    real(wp), intent(in) :: s(0:8)       !! relaxation rates
    logical, intent(in) :: bgk           !! E4 instead of E1
    real(wp), intent(in) :: force(2)     !! body force, lattice units
    coll%bgk = bgk
    coll%s_nu = s(7)
    if (bgk) then
      coll%s_e = s(7)
      coll%s_eps = s(7)
      coll%s_q = s(7)
    else
      coll%s_e = s(1)
      coll%s_eps = s(2)
      coll%s_q = s(4)
    end if
    coll%force = force
    coll%forced = any(force /= 0.0_wp)
  end subroutine collision_init

  !> The nine rates in moment order (rho, e, eps, jx, qx, jy, qy, pxx, pxy).
  pure function collision_describe(coll) result(s)
    type(collision_t), intent(in) :: coll
    real(wp) :: s(0:8)
    s = [0.0_wp, coll%s_e, coll%s_eps, 0.0_wp, coll%s_q, 0.0_wp, coll%s_q, coll%s_nu, coll%s_nu]
  end function collision_describe

  !> Fused pull-stream + collide over rows j1..j2 of a slab. Ghost columns 0 and nx+1 and
  !! halo rows 0 and nyl+1 of fin must hold what the boundary rules give (dkt_boundary).
  subroutine stream_collide(coll, fin, fout, nxp, nx, nyl, j1, j2)
    type(collision_t), intent(in) :: coll
    integer, intent(in) :: nxp, nx, nyl          !! padded x extent, columns, slab rows
    real(wp), intent(in) :: fin(0:nxp - 1, 0:nyl + 1, 0:8)
    real(wp), intent(inout) :: fout(0:nxp - 1, 0:nyl + 1, 0:8)
    integer, intent(in) :: j1, j2                !! rows to update
    integer :: j
    do j = j1, j2
      call collide_row(coll, fin, fout, nxp, nx, nyl, j)
    end do
  end subroutine stream_collide

  !> One row of E1 (MRT) or E4 (BGK). The force switch is a literal at each call of the node
  !! routine, so the inlined copy of the unforced loop carries no force terms and vectorises.
  subroutine collide_row(coll, fin, fout, nxp, nx, nyl, j)
    type(collision_t), intent(in) :: coll
    integer, intent(in) :: nxp, nx, nyl, j
    real(wp), intent(in) :: fin(0:nxp - 1, 0:nyl + 1, 0:8)
    real(wp), intent(inout) :: fout(0:nxp - 1, 0:nyl + 1, 0:8)
    integer :: x

    if (coll%bgk) then
      if (coll%forced) then
        do concurrent(x=1:nx)
          call bgk_node(coll, .true., fin, fout, nxp, nyl, x, j)
        end do
      else
        do concurrent(x=1:nx)
          call bgk_node(coll, .false., fin, fout, nxp, nyl, x, j)
        end do
      end if
    else
      if (coll%forced) then
        do concurrent(x=1:nx)
          call mrt_node(coll, .true., fin, fout, nxp, nyl, x, j)
        end do
      else
        do concurrent(x=1:nx)
          call mrt_node(coll, .false., fin, fout, nxp, nyl, x, j)
        end do
      end if
    end if
  end subroutine collide_row

  !> Pull, collide (E1 with the E2 equilibria and E3 rates) and store at node (x, j).
  pure subroutine mrt_node(coll, forced, fin, fout, nxp, nyl, x, j)
    type(collision_t), intent(in) :: coll
    logical, intent(in) :: forced !! include the body-force terms
    integer, intent(in) :: nxp, nyl, x, j
    real(wp), intent(in) :: fin(0:nxp - 1, 0:nyl + 1, 0:8)
    real(wp), intent(inout) :: fout(0:nxp - 1, 0:nyl + 1, 0:8)
    real(wp) :: f0, f1, f2, f3, f4, f5, f6, f7, f8
    real(wp) :: rho, rinv, me, meps, jx, qx, jy, qy, pxx, pxy, ux, uy, usq, ruf
    real(wp) :: a, b, c, g, p, r, s, t1, t5, gx1, gx5, gy1, gy5
    real(wp) :: ke, keps, kq, knu

    ! rates scaled by the row norms of M, so the relaxed moments come out as the
    ! coefficients of M^-1 = M^T D^-1 directly
    ke = coll%s_e/36.0_wp
    keps = coll%s_eps/36.0_wp
    kq = coll%s_q/12.0_wp
    knu = coll%s_nu/4.0_wp

    ! streaming: pull f*(x - e_i)
    f0 = fin(x, j, 0)
    f1 = fin(x - 1, j, 1)
    f2 = fin(x, j - 1, 2)
    f3 = fin(x + 1, j, 3)
    f4 = fin(x, j + 1, 4)
    f5 = fin(x - 1, j - 1, 5)
    f6 = fin(x + 1, j - 1, 6)
    f7 = fin(x + 1, j + 1, 7)
    f8 = fin(x - 1, j + 1, 8)

    ! m = M f (E1)
    a = f1 + f2 + f3 + f4
    b = f5 + f6 + f7 + f8
    rho = f0 + a + b
    me = -4.0_wp*f0 - a + 2.0_wp*b
    meps = 4.0_wp*f0 - 2.0_wp*a + b
    c = f5 - f6 - f7 + f8
    jx = f1 - f3 + c
    qx = -2.0_wp*(f1 - f3) + c
    c = f5 + f6 - f7 - f8
    jy = f2 - f4 + c
    qy = -2.0_wp*(f2 - f4) + c
    pxx = f1 - f2 + f3 - f4
    pxy = f5 - f6 + f7 - f8

    rinv = 1.0_wp/rho
    if (forced) then
      ux = (jx + 0.5_wp*coll%force(1))*rinv
      uy = (jy + 0.5_wp*coll%force(2))*rinv
    else
      ux = jx*rinv
      uy = jy*rinv
    end if
    usq = ux*ux + uy*uy

    ! m* - m = -S (m - m^eq) with the E2 equilibria and E3 rates, divided by the row norms
    ! (the conserved rho, jx, jy do not change)
    b = -ke*(me - rho*(-2.0_wp + 3.0_wp*usq))
    c = -keps*(meps - rho*(1.0_wp - 3.0_wp*usq))
    g = -kq*(qx + rho*ux)
    p = -kq*(qy + rho*uy)
    r = -knu*(pxx - rho*(ux*ux - uy*uy))
    s = -knu*(pxy - rho*ux*uy)
    if (forced) then
      ! Guo forcing in moment space: m* += (1 - s/2) F_m; jx, jy gain the full force
      ruf = ux*coll%force(1) + uy*coll%force(2)
      b = b + (1.0_wp - 0.5_wp*coll%s_e)*ruf/6.0_wp
      c = c - (1.0_wp - 0.5_wp*coll%s_eps)*ruf/6.0_wp
      g = g - (1.0_wp - 0.5_wp*coll%s_q)*coll%force(1)/12.0_wp
      p = p - (1.0_wp - 0.5_wp*coll%s_q)*coll%force(2)/12.0_wp
      r = r + (1.0_wp - 0.5_wp*coll%s_nu)*(ux*coll%force(1) - uy*coll%force(2))*0.5_wp
      s = s + (1.0_wp - 0.5_wp*coll%s_nu)*(ux*coll%force(2) + uy*coll%force(1))*0.25_wp
      gx1 = coll%force(1)/6.0_wp - 2.0_wp*g
      gx5 = coll%force(1)/6.0_wp + g
      gy1 = coll%force(2)/6.0_wp - 2.0_wp*p
      gy5 = coll%force(2)/6.0_wp + p
    else
      gx1 = -2.0_wp*g
      gx5 = g
      gy1 = -2.0_wp*p
      gy5 = p
    end if

    ! f* = f + M^T D^-1 (m* - m)
    t1 = -b - 2.0_wp*c
    t5 = 2.0_wp*b + c
    fout(x, j, 0) = f0 - 4.0_wp*(b - c)
    fout(x, j, 1) = f1 + t1 + gx1 + r
    fout(x, j, 2) = f2 + t1 + gy1 - r
    fout(x, j, 3) = f3 + t1 - gx1 + r
    fout(x, j, 4) = f4 + t1 - gy1 - r
    fout(x, j, 5) = f5 + t5 + gx5 + gy5 + s
    fout(x, j, 6) = f6 + t5 - gx5 + gy5 - s
    fout(x, j, 7) = f7 + t5 - gx5 - gy5 + s
    fout(x, j, 8) = f8 + t5 + gx5 - gy5 - s
  end subroutine mrt_node

  !> Pull and collide with E4 at node (x, j): f* = f - (f - f^eq)/tau + (1 - 1/(2 tau)) F_i,
  !! Guo's forcing F_i.
  pure subroutine bgk_node(coll, forced, fin, fout, nxp, nyl, x, j)
    type(collision_t), intent(in) :: coll
    logical, intent(in) :: forced !! include the body-force terms
    integer, intent(in) :: nxp, nyl, x, j
    real(wp), intent(in) :: fin(0:nxp - 1, 0:nyl + 1, 0:8)
    real(wp), intent(inout) :: fout(0:nxp - 1, 0:nyl + 1, 0:8)
    real(wp) :: f0, f1, f2, f3, f4, f5, f6, f7, f8
    real(wp) :: rho, rinv, ux, uy, usq, om, cf, fx, fy, base, rw1, rw5, eu, euf, ruf
    real(wp), parameter :: w0 = 4.0_wp/9.0_wp, w1 = 1.0_wp/9.0_wp, w5 = 1.0_wp/36.0_wp

    om = coll%s_nu
    fx = coll%force(1); fy = coll%force(2)
    cf = 1.0_wp - 0.5_wp*om

    f0 = fin(x, j, 0)
    f1 = fin(x - 1, j, 1)
    f2 = fin(x, j - 1, 2)
    f3 = fin(x + 1, j, 3)
    f4 = fin(x, j + 1, 4)
    f5 = fin(x - 1, j - 1, 5)
    f6 = fin(x + 1, j - 1, 6)
    f7 = fin(x + 1, j + 1, 7)
    f8 = fin(x - 1, j + 1, 8)
    rho = f0 + f1 + f2 + f3 + f4 + f5 + f6 + f7 + f8
    ux = f1 - f3 + f5 - f6 - f7 + f8
    uy = f2 - f4 + f5 + f6 - f7 - f8
    if (forced) then
      ux = ux + 0.5_wp*fx
      uy = uy + 0.5_wp*fy
    end if
    rinv = 1.0_wp/rho
    ux = ux*rinv
    uy = uy*rinv
    usq = 1.5_wp*(ux*ux + uy*uy)
    base = 1.0_wp - usq
    rw1 = om*w1*rho
    rw5 = om*w5*rho
    ! f_i^eq = w_i rho (1 + 3 eu + 4.5 eu^2 - 1.5 u^2)
    fout(x, j, 0) = f0 - om*(f0 - w0*rho*base)
    fout(x, j, 1) = f1 - (om*f1 - rw1*(base + 3.0_wp*ux + 4.5_wp*ux*ux))
    fout(x, j, 2) = f2 - (om*f2 - rw1*(base + 3.0_wp*uy + 4.5_wp*uy*uy))
    fout(x, j, 3) = f3 - (om*f3 - rw1*(base - 3.0_wp*ux + 4.5_wp*ux*ux))
    fout(x, j, 4) = f4 - (om*f4 - rw1*(base - 3.0_wp*uy + 4.5_wp*uy*uy))
    eu = ux + uy
    fout(x, j, 5) = f5 - (om*f5 - rw5*(base + 3.0_wp*eu + 4.5_wp*eu*eu))
    fout(x, j, 7) = f7 - (om*f7 - rw5*(base - 3.0_wp*eu + 4.5_wp*eu*eu))
    eu = uy - ux
    fout(x, j, 6) = f6 - (om*f6 - rw5*(base + 3.0_wp*eu + 4.5_wp*eu*eu))
    fout(x, j, 8) = f8 - (om*f8 - rw5*(base - 3.0_wp*eu + 4.5_wp*eu*eu))
    if (forced) then
      ! Guo: F_i = w_i [3 (e_i - u).F + 9 (e_i.u)(e_i.F)]
      ruf = ux*fx + uy*fy
      fout(x, j, 0) = fout(x, j, 0) + cf*w0*(-3.0_wp*ruf)
      fout(x, j, 1) = fout(x, j, 1) + cf*w1*(3.0_wp*(fx - ruf) + 9.0_wp*ux*fx)
      fout(x, j, 2) = fout(x, j, 2) + cf*w1*(3.0_wp*(fy - ruf) + 9.0_wp*uy*fy)
      fout(x, j, 3) = fout(x, j, 3) + cf*w1*(3.0_wp*(-fx - ruf) + 9.0_wp*ux*fx)
      fout(x, j, 4) = fout(x, j, 4) + cf*w1*(3.0_wp*(-fy - ruf) + 9.0_wp*uy*fy)
      eu = ux + uy
      euf = fx + fy
      fout(x, j, 5) = fout(x, j, 5) + cf*w5*(3.0_wp*(euf - ruf) + 9.0_wp*eu*euf)
      fout(x, j, 7) = fout(x, j, 7) + cf*w5*(3.0_wp*(-euf - ruf) + 9.0_wp*eu*euf)
      eu = uy - ux
      euf = fy - fx
      fout(x, j, 6) = fout(x, j, 6) + cf*w5*(3.0_wp*(euf - ruf) + 9.0_wp*eu*euf)
      fout(x, j, 8) = fout(x, j, 8) + cf*w5*(3.0_wp*(-euf - ruf) + 9.0_wp*eu*euf)
    end if
  end subroutine bgk_node

end module dkt_mrt

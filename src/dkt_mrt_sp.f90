!> The collision (docs/model.md E1–E4, Guo forcing) and the fused pull-stream + collide sweep in
!> 4-byte arithmetic, for lbm.precision = 'single_arith'.
!>
!> The lattice stores the deviations d_i = f_i - w_i in 4 bytes (dkt_store), and here they are
!> collided as such, never with w_i added back: a 24-bit significand spent on the constant w_i
!> would leave the flow's deviations (1e-3..1e-6 of f_i at low Mach number) a few bits, which is
!> why storage in 4 bytes is shifted in the first place. The moments of w are the rest state,
!> m(w) = (1, -2, 1, 0, 0, 0, 0, 0, 0) in the order (rho, e, eps, jx, qx, jy, qy, pxx, pxy), so
!> with rho = 1 + drho every m - m^eq is formed from small numbers only:
!>
!>     e   - e^eq   = e(d) + 2 drho - 3 rho|u|^2,    eps - eps^eq = eps(d) - drho + 3 rho|u|^2,
!>     q_x - q_x^eq = q_x(d) + rho u_x,              p_xx - p_xx^eq = p_xx(d) - rho (u_x^2 - u_y^2),
!>
!> and for BGK f_i^eq - w_i = w_i [drho + 3 e_i.j + 4.5 (e_i.j)(e_i.u) - 1.5 j.u] with j = rho u.
!> The post-collision deviation is d_i plus the same M^T D^-1 (m* - m) as in 8 bytes (dkt_mrt).
!> The rates and the force are rounded to 4 bytes once (collision_sp_set); everything around the
!> sweep (boundaries, bounce-back, momentum exchange, particles) stays in 8 bytes.
!>
!> The layout follows dkt_mrt: rows along x, one node routine per loop, inlined, with the
!> collision model and the force switch as literals, so that each x loop vectorises.
module dkt_mrt_sp
  use dkt_kinds, only: wp, sp
  implicit none
  private
  public :: collision_sp_t, collision_sp_set, collide_sp, rows_sp, rows_in_place_sp, &
            rows_from_rows_sp

  !> The rates and the force of dkt_mrt's collision_t in 4 bytes, with the constant factors
  !! of the MRT relaxation and of Guo's term taken once.
  type, public :: collision_sp_t
    logical :: bgk = .false.
    logical :: forced = .false.
    real(sp) :: ke = 0, keps = 0, kq = 0, knu = 0 !! MRT rates over the row norms 36, 36, 12, 4
    real(sp) :: fx = 0, fy = 0                    !! body force, lattice units
    real(sp) :: fx6 = 0, fy6 = 0                  !! force / 6 (the j rows of M^T D^-1)
    real(sp) :: ce = 0, ceps = 0                  !! Guo: (1 - s_e/2)/6, (1 - s_eps/2)/6
    real(sp) :: gqx = 0, gqy = 0                  !! Guo: (1 - s_q/2) F/12
    real(sp) :: cr = 0, cs = 0                    !! Guo: (1 - s_nu/2)/2, (1 - s_nu/2)/4
    real(sp) :: om = 0, cf = 0                    !! BGK: 1/tau and 1 - 1/(2 tau)
  end type collision_sp_t

  real(sp), parameter :: w0 = 4.0_sp/9.0_sp, w1 = 1.0_sp/9.0_sp, w5 = 1.0_sp/36.0_sp

contains

  !> The 4-byte collision of the rates (E3) and the body force of an 8-byte one.
  pure subroutine collision_sp_set(c, bgk, s_nu, s_e, s_eps, s_q, force)
    type(collision_sp_t), intent(out) :: c
    logical, intent(in) :: bgk
    real(wp), intent(in) :: s_nu, s_e, s_eps, s_q !! relaxation rates
    real(wp), intent(in) :: force(2)              !! body force, lattice units
    c%bgk = bgk
    c%forced = any(force /= 0.0_wp)
    c%ke = real(s_e/36.0_wp, sp)
    c%keps = real(s_eps/36.0_wp, sp)
    c%kq = real(s_q/12.0_wp, sp)
    c%knu = real(s_nu/4.0_wp, sp)
    c%fx = real(force(1), sp)
    c%fy = real(force(2), sp)
    c%fx6 = real(force(1)/6.0_wp, sp)
    c%fy6 = real(force(2)/6.0_wp, sp)
    c%ce = real((1.0_wp - 0.5_wp*s_e)/6.0_wp, sp)
    c%ceps = real((1.0_wp - 0.5_wp*s_eps)/6.0_wp, sp)
    c%gqx = real((1.0_wp - 0.5_wp*s_q)*force(1)/12.0_wp, sp)
    c%gqy = real((1.0_wp - 0.5_wp*s_q)*force(2)/12.0_wp, sp)
    c%cr = real((1.0_wp - 0.5_wp*s_nu)*0.5_wp, sp)
    c%cs = real((1.0_wp - 0.5_wp*s_nu)*0.25_wp, sp)
    c%om = real(s_nu, sp)
    c%cf = real(1.0_wp - 0.5_wp*s_nu, sp)
  end subroutine collision_sp_set

  !> Row j from one 4-byte lattice into another (the stored values are the deviations).
  subroutine rows_sp(c, fin, fout, nxp, nx, nyl, j)
    type(collision_sp_t), intent(in) :: c
    integer, intent(in) :: nxp, nx, nyl, j
    real(sp), intent(in) :: fin(0:nxp - 1, 0:nyl + 1, 0:8)
    real(sp), intent(inout) :: fout(0:nxp - 1, 0:nyl + 1, 0:8)
    integer :: x
    if (c%bgk) then
      if (c%forced) then
        do concurrent(x=1:nx)
          call node_sp(c, .true., .true., fin, fout, nxp, nyl, x, j)
        end do
      else
        do concurrent(x=1:nx)
          call node_sp(c, .true., .false., fin, fout, nxp, nyl, x, j)
        end do
      end if
    else
      if (c%forced) then
        do concurrent(x=1:nx)
          call node_sp(c, .false., .true., fin, fout, nxp, nyl, x, j)
        end do
      else
        do concurrent(x=1:nx)
          call node_sp(c, .false., .false., fin, fout, nxp, nyl, x, j)
        end do
      end if
    end if
  end subroutine rows_sp

  !> Row j in place (docs/design.md, "In-place streaming"), with 4-byte row buffers: below holds
  !! old row j-1's deviations 2, 5, 6; old row j's go to saved; the new 1 and 3 are stored from
  !! o13 once the row is done.
  subroutine rows_in_place_sp(c, f, below, saved, o13, nxp, nx, nyl, j)
    type(collision_sp_t), intent(in) :: c
    integer, intent(in) :: nxp, nx, nyl, j
    real(sp), intent(inout) :: f(0:nxp - 1, 0:nyl + 1, 0:8)
    real(sp), intent(in) :: below(0:nxp - 1, 3)
    real(sp), intent(inout) :: saved(0:nxp - 1, 3), o13(0:nxp - 1, 2)
    integer, parameter :: up3(3) = [2, 5, 6]
    integer :: x, k
    if (c%bgk) then
      if (c%forced) then
        do concurrent(x=1:nx)
          call node_in_place_sp(c, .true., .true., f, below, saved, o13, nxp, nyl, x, j)
        end do
      else
        do concurrent(x=1:nx)
          call node_in_place_sp(c, .true., .false., f, below, saved, o13, nxp, nyl, x, j)
        end do
      end if
    else
      if (c%forced) then
        do concurrent(x=1:nx)
          call node_in_place_sp(c, .false., .true., f, below, saved, o13, nxp, nyl, x, j)
        end do
      else
        do concurrent(x=1:nx)
          call node_in_place_sp(c, .false., .false., f, below, saved, o13, nxp, nyl, x, j)
        end do
      end if
    end if
    f(1:nx, j, 1) = o13(1:nx, 1)
    f(1:nx, j, 3) = o13(1:nx, 2)
    do k = 1, 3
      saved(0, k) = f(0, j, up3(k))
      saved(nx + 1, k) = f(nx + 1, j, up3(k))
    end do
  end subroutine rows_in_place_sp

  !> One row from decoded rows, for lbm.precision = 'half' (dkt_mrt_half): src holds the
  !! deviations a row pulls from its own row (0, 1, 3) and from the row above (4, 7, 8) at those
  !! population indices, below those of the row below (2, 5, 6); dst receives the nine
  !! post-collision deviations of columns 1..nx. Each node computes what node_sp computes.
  subroutine rows_from_rows_sp(c, src, below, dst, nxp, nx)
    type(collision_sp_t), intent(in) :: c
    integer, intent(in) :: nxp, nx
    real(sp), intent(in) :: src(0:nxp - 1, 0:8), below(0:nxp - 1, 3)
    real(sp), intent(inout) :: dst(0:nxp - 1, 0:8)
    integer :: x
    if (c%bgk) then
      if (c%forced) then
        do concurrent(x=1:nx)
          call node_from_rows_sp(c, .true., .true., src, below, dst, nxp, x)
        end do
      else
        do concurrent(x=1:nx)
          call node_from_rows_sp(c, .true., .false., src, below, dst, nxp, x)
        end do
      end if
    else
      if (c%forced) then
        do concurrent(x=1:nx)
          call node_from_rows_sp(c, .false., .true., src, below, dst, nxp, x)
        end do
      else
        do concurrent(x=1:nx)
          call node_from_rows_sp(c, .false., .false., src, below, dst, nxp, x)
        end do
      end if
    end if
  end subroutine rows_from_rows_sp

  pure subroutine node_from_rows_sp(c, bgk, forced, src, below, dst, nxp, x)
    type(collision_sp_t), intent(in) :: c
    logical, intent(in) :: bgk, forced
    integer, intent(in) :: nxp, x
    real(sp), intent(in) :: src(0:nxp - 1, 0:8), below(0:nxp - 1, 3)
    real(sp), intent(inout) :: dst(0:nxp - 1, 0:8)
    real(sp) :: d0, d1, d2, d3, d4, d5, d6, d7, d8
    d0 = src(x, 0)
    d1 = src(x - 1, 1)
    d2 = below(x, 1)
    d3 = src(x + 1, 3)
    d4 = src(x, 4)
    d5 = below(x - 1, 2)
    d6 = below(x + 1, 3)
    d7 = src(x + 1, 7)
    d8 = src(x - 1, 8)
    call collide_sp(c, bgk, forced, d0, d1, d2, d3, d4, d5, d6, d7, d8)
    dst(x, 0) = d0
    dst(x, 1) = d1
    dst(x, 2) = d2
    dst(x, 3) = d3
    dst(x, 4) = d4
    dst(x, 5) = d5
    dst(x, 6) = d6
    dst(x, 7) = d7
    dst(x, 8) = d8
  end subroutine node_from_rows_sp

  !> Two lattices: pull into node (x, j) of fin, collide, store in fout.
  pure subroutine node_sp(c, bgk, forced, fin, fout, nxp, nyl, x, j)
    type(collision_sp_t), intent(in) :: c
    logical, intent(in) :: bgk, forced
    integer, intent(in) :: nxp, nyl, x, j
    real(sp), intent(in) :: fin(0:nxp - 1, 0:nyl + 1, 0:8)
    real(sp), intent(inout) :: fout(0:nxp - 1, 0:nyl + 1, 0:8)
    real(sp) :: d0, d1, d2, d3, d4, d5, d6, d7, d8
    d0 = fin(x, j, 0)
    d1 = fin(x - 1, j, 1)
    d2 = fin(x, j - 1, 2)
    d3 = fin(x + 1, j, 3)
    d4 = fin(x, j + 1, 4)
    d5 = fin(x - 1, j - 1, 5)
    d6 = fin(x + 1, j - 1, 6)
    d7 = fin(x + 1, j + 1, 7)
    d8 = fin(x - 1, j + 1, 8)
    call collide_sp(c, bgk, forced, d0, d1, d2, d3, d4, d5, d6, d7, d8)
    fout(x, j, 0) = d0
    fout(x, j, 1) = d1
    fout(x, j, 2) = d2
    fout(x, j, 3) = d3
    fout(x, j, 4) = d4
    fout(x, j, 5) = d5
    fout(x, j, 6) = d6
    fout(x, j, 7) = d7
    fout(x, j, 8) = d8
  end subroutine node_sp

  !> In place, node (x, j): dkt_mrt's node_in_place_d on 4-byte deviations.
  pure subroutine node_in_place_sp(c, bgk, forced, f, below, saved, o13, nxp, nyl, x, j)
    type(collision_sp_t), intent(in) :: c
    logical, intent(in) :: bgk, forced
    integer, intent(in) :: nxp, nyl, x, j
    real(sp), intent(inout) :: f(0:nxp - 1, 0:nyl + 1, 0:8)
    real(sp), intent(in) :: below(0:nxp - 1, 3)
    real(sp), intent(inout) :: saved(0:nxp - 1, 3), o13(0:nxp - 1, 2)
    real(sp) :: d0, d1, d2, d3, d4, d5, d6, d7, d8
    d0 = f(x, j, 0)
    d1 = f(x - 1, j, 1)
    d2 = below(x, 1)
    d3 = f(x + 1, j, 3)
    d4 = f(x, j + 1, 4)
    d5 = below(x - 1, 2)
    d6 = below(x + 1, 3)
    d7 = f(x + 1, j + 1, 7)
    d8 = f(x - 1, j + 1, 8)
    saved(x, 1) = f(x, j, 2)
    saved(x, 2) = f(x, j, 5)
    saved(x, 3) = f(x, j, 6)
    call collide_sp(c, bgk, forced, d0, d1, d2, d3, d4, d5, d6, d7, d8)
    f(x, j, 0) = d0
    o13(x, 1) = d1
    f(x, j, 2) = d2
    o13(x, 2) = d3
    f(x, j, 4) = d4
    f(x, j, 5) = d5
    f(x, j, 6) = d6
    f(x, j, 7) = d7
    f(x, j, 8) = d8
  end subroutine node_in_place_sp

  !> E1 (MRT) or E4 (BGK) at one node, on the deviations d_i = f_i - w_i.
  pure subroutine collide_sp(c, bgk, forced, d0, d1, d2, d3, d4, d5, d6, d7, d8)
    type(collision_sp_t), intent(in) :: c
    logical, intent(in) :: bgk, forced
    !> in: the deviations pulled into the node; out: post-collision
    real(sp), intent(inout) :: d0, d1, d2, d3, d4, d5, d6, d7, d8
    if (bgk) then
      call bgk_collide_sp(c, forced, d0, d1, d2, d3, d4, d5, d6, d7, d8)
    else
      call mrt_collide_sp(c, forced, d0, d1, d2, d3, d4, d5, d6, d7, d8)
    end if
  end subroutine collide_sp

  pure subroutine mrt_collide_sp(c, forced, d0, d1, d2, d3, d4, d5, d6, d7, d8)
    type(collision_sp_t), intent(in) :: c
    logical, intent(in) :: forced !! include the body-force terms
    real(sp), intent(inout) :: d0, d1, d2, d3, d4, d5, d6, d7, d8
    real(sp) :: drho, rinv, me, meps, jx, qx, jy, qy, pxx, pxy, ux, uy, rusq, ruf
    real(sp) :: a, b, e, g, p, r, s, t1, t5, gx1, gx5, gy1, gy5

    ! m(d) = M d (E1): the moments of f less those of w (1, -2, 1, 0, ...)
    a = d1 + d2 + d3 + d4
    b = d5 + d6 + d7 + d8
    drho = d0 + a + b
    me = -4.0_sp*d0 - a + 2.0_sp*b
    meps = 4.0_sp*d0 - 2.0_sp*a + b
    e = d5 - d6 - d7 + d8
    jx = d1 - d3 + e
    qx = -2.0_sp*(d1 - d3) + e
    e = d5 + d6 - d7 - d8
    jy = d2 - d4 + e
    qy = -2.0_sp*(d2 - d4) + e
    pxx = d1 - d2 + d3 - d4
    pxy = d5 - d6 + d7 - d8

    ! rho u with Guo's half force; rho = 1 + drho
    if (forced) then
      jx = jx + 0.5_sp*c%fx
      jy = jy + 0.5_sp*c%fy
    end if
    rinv = 1.0_sp/(1.0_sp + drho)
    ux = jx*rinv
    uy = jy*rinv
    rusq = jx*ux + jy*uy

    ! m* - m = -S (m - m^eq) over the row norms, m - m^eq in deviation form (module header)
    b = -c%ke*(me + 2.0_sp*drho - 3.0_sp*rusq)
    e = -c%keps*(meps - drho + 3.0_sp*rusq)
    g = -c%kq*(qx + jx)
    p = -c%kq*(qy + jy)
    r = -c%knu*(pxx - (jx*ux - jy*uy))
    s = -c%knu*(pxy - jx*uy)
    if (forced) then
      ! Guo forcing in moment space: m* += (1 - s/2) F_m; jx, jy gain the full force
      ruf = ux*c%fx + uy*c%fy
      b = b + c%ce*ruf
      e = e - c%ceps*ruf
      g = g - c%gqx
      p = p - c%gqy
      r = r + c%cr*(ux*c%fx - uy*c%fy)
      s = s + c%cs*(ux*c%fy + uy*c%fx)
      gx1 = c%fx6 - 2.0_sp*g
      gx5 = c%fx6 + g
      gy1 = c%fy6 - 2.0_sp*p
      gy5 = c%fy6 + p
    else
      gx1 = -2.0_sp*g
      gx5 = g
      gy1 = -2.0_sp*p
      gy5 = p
    end if

    ! d* = d + M^T D^-1 (m* - m)
    t1 = -b - 2.0_sp*e
    t5 = 2.0_sp*b + e
    d0 = d0 - 4.0_sp*(b - e)
    d1 = d1 + t1 + gx1 + r
    d2 = d2 + t1 + gy1 - r
    d3 = d3 + t1 - gx1 + r
    d4 = d4 + t1 - gy1 - r
    d5 = d5 + t5 + gx5 + gy5 + s
    d6 = d6 + t5 - gx5 + gy5 - s
    d7 = d7 + t5 - gx5 - gy5 + s
    d8 = d8 + t5 + gx5 - gy5 - s
  end subroutine mrt_collide_sp

  pure subroutine bgk_collide_sp(c, forced, d0, d1, d2, d3, d4, d5, d6, d7, d8)
    type(collision_sp_t), intent(in) :: c
    logical, intent(in) :: forced !! include the body-force terms
    real(sp), intent(inout) :: d0, d1, d2, d3, d4, d5, d6, d7, d8
    real(sp) :: drho, rinv, jx, jy, ux, uy, base, ej, eu, ruf, euf, om
    real(sp) :: q0, q1, q2, q3, q4, q5, q6, q7, q8

    om = c%om
    drho = d0 + d1 + d2 + d3 + d4 + d5 + d6 + d7 + d8
    jx = d1 - d3 + d5 - d6 - d7 + d8
    jy = d2 - d4 + d5 + d6 - d7 - d8
    if (forced) then
      jx = jx + 0.5_sp*c%fx
      jy = jy + 0.5_sp*c%fy
    end if
    rinv = 1.0_sp/(1.0_sp + drho)
    ux = jx*rinv
    uy = jy*rinv
    ! f_i^eq - w_i = w_i [drho + 3 e.j + 4.5 (e.j)(e.u) - 1.5 j.u]
    base = drho - 1.5_sp*(jx*ux + jy*uy)
    q0 = d0 - om*(d0 - w0*base)
    q1 = d1 - om*(d1 - w1*(base + 3.0_sp*jx + 4.5_sp*jx*ux))
    q2 = d2 - om*(d2 - w1*(base + 3.0_sp*jy + 4.5_sp*jy*uy))
    q3 = d3 - om*(d3 - w1*(base - 3.0_sp*jx + 4.5_sp*jx*ux))
    q4 = d4 - om*(d4 - w1*(base - 3.0_sp*jy + 4.5_sp*jy*uy))
    ej = jx + jy
    eu = ux + uy
    q5 = d5 - om*(d5 - w5*(base + 3.0_sp*ej + 4.5_sp*ej*eu))
    q7 = d7 - om*(d7 - w5*(base - 3.0_sp*ej + 4.5_sp*ej*eu))
    ej = jy - jx
    eu = uy - ux
    q6 = d6 - om*(d6 - w5*(base + 3.0_sp*ej + 4.5_sp*ej*eu))
    q8 = d8 - om*(d8 - w5*(base - 3.0_sp*ej + 4.5_sp*ej*eu))
    if (forced) then
      ! Guo: F_i = w_i [3 (e_i - u).F + 9 (e_i.u)(e_i.F)]
      associate (fx => c%fx, fy => c%fy, cf => c%cf)
        ruf = ux*fx + uy*fy
        q0 = q0 + cf*w0*(-3.0_sp*ruf)
        q1 = q1 + cf*w1*(3.0_sp*(fx - ruf) + 9.0_sp*ux*fx)
        q2 = q2 + cf*w1*(3.0_sp*(fy - ruf) + 9.0_sp*uy*fy)
        q3 = q3 + cf*w1*(3.0_sp*(-fx - ruf) + 9.0_sp*ux*fx)
        q4 = q4 + cf*w1*(3.0_sp*(-fy - ruf) + 9.0_sp*uy*fy)
        eu = ux + uy
        euf = fx + fy
        q5 = q5 + cf*w5*(3.0_sp*(euf - ruf) + 9.0_sp*eu*euf)
        q7 = q7 + cf*w5*(3.0_sp*(-euf - ruf) + 9.0_sp*eu*euf)
        eu = uy - ux
        euf = fy - fx
        q6 = q6 + cf*w5*(3.0_sp*(euf - ruf) + 9.0_sp*eu*euf)
        q8 = q8 + cf*w5*(3.0_sp*(-euf - ruf) + 9.0_sp*eu*euf)
      end associate
    end if
    d0 = q0; d1 = q1; d2 = q2; d3 = q3; d4 = q4; d5 = q5; d6 = q6; d7 = q7; d8 = q8
  end subroutine bgk_collide_sp

end module dkt_mrt_sp

!> The collision operator and the fused pull-stream + collide sweep (docs/model.md E1–E4).
!>
!> Arrays hold post-collision populations f*(x, t). One sweep pulls f*(x - e_i, t) into each
!> node (streaming), collides there and stores f*(x, t + 1) in the other lattice. The MRT
!> transform is written out (orthogonal rows, M^-1 = M^T D^-1) rather than a 9x9 product, and
!> the inner loop runs along x so that it vectorises. A uniform body force enters through
!> Guo's forcing term in moment space; a scene without one does not compute it.
module dkt_mrt
  use dkt_kinds, only: wp, sp
  use dkt_lattice, only: w
  use dkt_store, only: lattice_t
  implicit none
  private
  public :: collision_t, collision_init, stream_collide, collision_describe, e3_heat_flux_rate, &
            sweep_t, sweep_init, sweep_rows

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

  !> The row buffers of sweep_rows, allocated once per run (sweep_init).
  type, public :: sweep_t
    real(wp), allocatable :: ring(:, :, :)  !! (0:nxp-1, 0:2, 0:8): src rows j-1, j, j+1 mod 3
    real(wp), allocatable :: orow(:, :, :)  !! (0:nxp-1, 0:0, 0:8): a collided row, 8 bytes
    real(wp), allocatable :: kept_lo(:, :)  !! (0:nxp-1, 0:8): an old row kept for the part above
    real(wp), allocatable :: kept_hi(:, :)  !! the same for the part below
  end type sweep_t

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

  !> Fused pull-stream + collide over rows j1..j2 of a slab, from one double lattice into
  !! another. Ghost columns 0 and nx+1 and halo rows 0 and nyl+1 of fin must hold what the
  !! boundary rules give (dkt_boundary).
  subroutine stream_collide(coll, fin, fout, nxp, nx, nyl, j1, j2)
    type(collision_t), intent(in) :: coll
    integer, intent(in) :: nxp, nx, nyl          !! padded x extent, columns, slab rows
    real(wp), intent(in) :: fin(0:nxp - 1, 0:nyl + 1, 0:8)
    real(wp), intent(inout) :: fout(0:nxp - 1, 0:nyl + 1, 0:8)
    integer, intent(in) :: j1, j2                !! rows to update
    integer :: j
    do j = j1, j2
      call collide_row(coll, fin, nyl, j - 1, j, j + 1, fout, 0, nyl + 1, j, nxp, nx)
    end do
  end subroutine stream_collide

  !> Row buffers of the row-by-row sweep (sweep_rows), for one slab.
  subroutine sweep_init(ws, nxp)
    type(sweep_t), intent(out) :: ws
    integer, intent(in) :: nxp
    allocate (ws%ring(0:nxp - 1, 0:2, 0:8), ws%orow(0:nxp - 1, 0:0, 0:8))
    allocate (ws%kept_lo(0:nxp - 1, 0:8), ws%kept_hi(0:nxp - 1, 0:8))
    ws%ring = 0.0_wp
    ws%orow = 0.0_wp
    ws%kept_lo = 0.0_wp
    ws%kept_hi = 0.0_wp
  end subroutine sweep_init

  !> Pull-stream + collide rows j1..j2 from src into dst, row by row through a ring of three
  !! 8-byte rows: the rows j-1, j, j+1 of src, unshifted, are in the ring when row j is
  !! collided, so dst may be src itself (in-place streaming: each row is read from memory once
  !! and written once, and a row is overwritten only after the rows that pull from it have it in
  !! the ring) and src may be stored in 4 bytes (the collision is computed in 8 all the same).
  !! With src and dst in double and distinct, the result has the bits of stream_collide.
  !!
  !! When the sweep of a slab is split in parts (dkt_simulation overlaps the halo exchange with
  !! the rows that do not need it), an in-place part can keep the old rows j1 and j2 it
  !! overwrites (keep: into kept_lo and kept_hi) for the parts beside it, which then take their
  !! row j1-1 from kept_hi (below_kept) or their row j2+1 from kept_lo (above_kept).
  subroutine sweep_rows(coll, ws, src, dst, nx, nyl, j1, j2, keep, below_kept, above_kept)
    type(collision_t), intent(in) :: coll
    type(sweep_t), intent(inout) :: ws
    type(lattice_t), intent(in) :: src
    type(lattice_t), intent(inout) :: dst
    integer, intent(in) :: nx, nyl, j1, j2
    logical, intent(in), optional :: keep, below_kept, above_kept
    integer :: j, nxp, i
    nxp = size(ws%ring, 1)
    if (j2 < j1) return
    if (opt(below_kept)) then
      ws%ring(:, slot(j1 - 1), :) = ws%kept_hi
    else
      call load_row(ws, src, j1 - 1, nx)
    end if
    call load_row(ws, src, j1, nx)
    if (opt(keep)) ws%kept_lo = ws%ring(:, slot(j1), :)
    do j = j1, j2
      if (j == j2 .and. opt(above_kept)) then
        ws%ring(:, slot(j + 1), :) = ws%kept_lo
      else
        call load_row(ws, src, j + 1, nx)
      end if
      if (dst%single) then
        call collide_row(coll, ws%ring, 1, slot(j - 1), slot(j), slot(j + 1), ws%orow, 0, 0, &
                         0, nxp, nx)
        if (dst%shifted) then
          do i = 0, 8
            dst%s(1:nx, j, i) = real(ws%orow(1:nx, 0, i) - w(i), sp)
          end do
        else
          do i = 0, 8
            dst%s(1:nx, j, i) = real(ws%orow(1:nx, 0, i), sp)
          end do
        end if
      else
        call collide_row(coll, ws%ring, 1, slot(j - 1), slot(j), slot(j + 1), dst%d, 0, &
                         nyl + 1, j, nxp, nx)
      end if
    end do
    if (opt(keep)) ws%kept_hi = ws%ring(:, slot(j2), :)
  contains
    pure integer function slot(r)
      integer, intent(in) :: r
      slot = modulo(r, 3)
    end function slot
    pure logical function opt(flag)
      logical, intent(in), optional :: flag
      opt = .false.
      if (present(flag)) opt = flag
    end function opt
    !> Row r of src (columns 0..nx+1, the ghosts included) into its ring slot, in 8 bytes.
    subroutine load_row(ws, src, r, nx)
      type(sweep_t), intent(inout) :: ws
      type(lattice_t), intent(in) :: src
      integer, intent(in) :: r, nx
      integer :: k
      if (src%single) then
        if (src%shifted) then
          do k = 0, 8
            ws%ring(0:nx + 1, slot(r), k) = real(src%s(0:nx + 1, r, k), wp) + w(k)
          end do
        else
          do k = 0, 8
            ws%ring(0:nx + 1, slot(r), k) = real(src%s(0:nx + 1, r, k), wp)
          end do
        end if
      else
        do k = 0, 8
          ws%ring(0:nx + 1, slot(r), k) = src%d(0:nx + 1, r, k)
        end do
      end if
    end subroutine load_row
  end subroutine sweep_rows

  !> One row of E1 (MRT) or E4 (BGK): pull from rows jm, j0, jp of fin (the rows below, at and
  !! above the node row) and store in row jo of fout. The force switch is a literal at each call
  !! of the node routine, so the inlined copy of the unforced loop carries no force terms and
  !! vectorises.
  subroutine collide_row(coll, fin, nyi, jm, j0, jp, fout, olo, ohi, jo, nxp, nx)
    type(collision_t), intent(in) :: coll
    integer, intent(in) :: nyi, jm, j0, jp, olo, ohi, jo, nxp, nx
    real(wp), intent(in) :: fin(0:nxp - 1, 0:nyi + 1, 0:8)
    real(wp), intent(inout) :: fout(0:nxp - 1, olo:ohi, 0:8)
    integer :: x

    if (coll%bgk) then
      if (coll%forced) then
        do concurrent(x=1:nx)
          call bgk_node(coll, .true., fin, nyi, jm, j0, jp, fout, olo, ohi, jo, nxp, x)
        end do
      else
        do concurrent(x=1:nx)
          call bgk_node(coll, .false., fin, nyi, jm, j0, jp, fout, olo, ohi, jo, nxp, x)
        end do
      end if
    else
      if (coll%forced) then
        do concurrent(x=1:nx)
          call mrt_node(coll, .true., fin, nyi, jm, j0, jp, fout, olo, ohi, jo, nxp, x)
        end do
      else
        do concurrent(x=1:nx)
          call mrt_node(coll, .false., fin, nyi, jm, j0, jp, fout, olo, ohi, jo, nxp, x)
        end do
      end if
    end if
  end subroutine collide_row

  !> Pull, collide (E1 with the E2 equilibria and E3 rates) and store at node (x, j).
  pure subroutine mrt_node(coll, forced, fin, nyi, jm, j0, jp, fout, olo, ohi, jo, nxp, x)
    type(collision_t), intent(in) :: coll
    logical, intent(in) :: forced !! include the body-force terms
    integer, intent(in) :: nxp, nyi, jm, j0, jp, olo, ohi, jo, x
    real(wp), intent(in) :: fin(0:nxp - 1, 0:nyi + 1, 0:8)     !! rows jm, j0, jp read
    real(wp), intent(inout) :: fout(0:nxp - 1, olo:ohi, 0:8)   !! row jo written
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
    f0 = fin(x, j0, 0)
    f1 = fin(x - 1, j0, 1)
    f2 = fin(x, jm, 2)
    f3 = fin(x + 1, j0, 3)
    f4 = fin(x, jp, 4)
    f5 = fin(x - 1, jm, 5)
    f6 = fin(x + 1, jm, 6)
    f7 = fin(x + 1, jp, 7)
    f8 = fin(x - 1, jp, 8)

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
    fout(x, jo, 0) = f0 - 4.0_wp*(b - c)
    fout(x, jo, 1) = f1 + t1 + gx1 + r
    fout(x, jo, 2) = f2 + t1 + gy1 - r
    fout(x, jo, 3) = f3 + t1 - gx1 + r
    fout(x, jo, 4) = f4 + t1 - gy1 - r
    fout(x, jo, 5) = f5 + t5 + gx5 + gy5 + s
    fout(x, jo, 6) = f6 + t5 - gx5 + gy5 - s
    fout(x, jo, 7) = f7 + t5 - gx5 - gy5 + s
    fout(x, jo, 8) = f8 + t5 + gx5 - gy5 - s
  end subroutine mrt_node

  !> Pull and collide with E4 at node (x, j): f* = f - (f - f^eq)/tau + (1 - 1/(2 tau)) F_i,
  !! Guo's forcing F_i.
  pure subroutine bgk_node(coll, forced, fin, nyi, jm, j0, jp, fout, olo, ohi, jo, nxp, x)
    type(collision_t), intent(in) :: coll
    logical, intent(in) :: forced !! include the body-force terms
    integer, intent(in) :: nxp, nyi, jm, j0, jp, olo, ohi, jo, x
    real(wp), intent(in) :: fin(0:nxp - 1, 0:nyi + 1, 0:8)     !! rows jm, j0, jp read
    real(wp), intent(inout) :: fout(0:nxp - 1, olo:ohi, 0:8)   !! row jo written
    real(wp) :: f0, f1, f2, f3, f4, f5, f6, f7, f8
    real(wp) :: rho, rinv, ux, uy, usq, om, cf, fx, fy, base, rw1, rw5, eu, euf, ruf
    real(wp), parameter :: w0 = 4.0_wp/9.0_wp, w1 = 1.0_wp/9.0_wp, w5 = 1.0_wp/36.0_wp

    om = coll%s_nu
    fx = coll%force(1); fy = coll%force(2)
    cf = 1.0_wp - 0.5_wp*om

    f0 = fin(x, j0, 0)
    f1 = fin(x - 1, j0, 1)
    f2 = fin(x, jm, 2)
    f3 = fin(x + 1, j0, 3)
    f4 = fin(x, jp, 4)
    f5 = fin(x - 1, jm, 5)
    f6 = fin(x + 1, jm, 6)
    f7 = fin(x + 1, jp, 7)
    f8 = fin(x - 1, jp, 8)
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
    fout(x, jo, 0) = f0 - om*(f0 - w0*rho*base)
    fout(x, jo, 1) = f1 - (om*f1 - rw1*(base + 3.0_wp*ux + 4.5_wp*ux*ux))
    fout(x, jo, 2) = f2 - (om*f2 - rw1*(base + 3.0_wp*uy + 4.5_wp*uy*uy))
    fout(x, jo, 3) = f3 - (om*f3 - rw1*(base - 3.0_wp*ux + 4.5_wp*ux*ux))
    fout(x, jo, 4) = f4 - (om*f4 - rw1*(base - 3.0_wp*uy + 4.5_wp*uy*uy))
    eu = ux + uy
    fout(x, jo, 5) = f5 - (om*f5 - rw5*(base + 3.0_wp*eu + 4.5_wp*eu*eu))
    fout(x, jo, 7) = f7 - (om*f7 - rw5*(base - 3.0_wp*eu + 4.5_wp*eu*eu))
    eu = uy - ux
    fout(x, jo, 6) = f6 - (om*f6 - rw5*(base + 3.0_wp*eu + 4.5_wp*eu*eu))
    fout(x, jo, 8) = f8 - (om*f8 - rw5*(base - 3.0_wp*eu + 4.5_wp*eu*eu))
    if (forced) then
      ! Guo: F_i = w_i [3 (e_i - u).F + 9 (e_i.u)(e_i.F)]
      ruf = ux*fx + uy*fy
      fout(x, jo, 0) = fout(x, jo, 0) + cf*w0*(-3.0_wp*ruf)
      fout(x, jo, 1) = fout(x, jo, 1) + cf*w1*(3.0_wp*(fx - ruf) + 9.0_wp*ux*fx)
      fout(x, jo, 2) = fout(x, jo, 2) + cf*w1*(3.0_wp*(fy - ruf) + 9.0_wp*uy*fy)
      fout(x, jo, 3) = fout(x, jo, 3) + cf*w1*(3.0_wp*(-fx - ruf) + 9.0_wp*ux*fx)
      fout(x, jo, 4) = fout(x, jo, 4) + cf*w1*(3.0_wp*(-fy - ruf) + 9.0_wp*uy*fy)
      eu = ux + uy
      euf = fx + fy
      fout(x, jo, 5) = fout(x, jo, 5) + cf*w5*(3.0_wp*(euf - ruf) + 9.0_wp*eu*euf)
      fout(x, jo, 7) = fout(x, jo, 7) + cf*w5*(3.0_wp*(-euf - ruf) + 9.0_wp*eu*euf)
      eu = uy - ux
      euf = fy - fx
      fout(x, jo, 6) = fout(x, jo, 6) + cf*w5*(3.0_wp*(euf - ruf) + 9.0_wp*eu*euf)
      fout(x, jo, 8) = fout(x, jo, 8) + cf*w5*(3.0_wp*(-euf - ruf) + 9.0_wp*eu*euf)
    end if
  end subroutine bgk_node

end module dkt_mrt

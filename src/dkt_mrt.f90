!> The collision operator and the fused pull-stream + collide sweep (docs/model.md E1–E4).
!>
!> Arrays hold post-collision populations f*(x, t). One sweep pulls f*(x - e_i, t) into each
!> node (streaming), collides there and stores f*(x, t + 1): into a second lattice
!> (lbm.streaming = 'two_lattice') or, row by row, into the same one ('in_place', docs/design.md).
!> The populations are stored in 8 or 4 bytes (lbm.precision, dkt_store) and collided in 8,
!> except with 'single_arith', whose 4-byte deviations are collided in 4 bytes (dkt_mrt_sp) with
!> 4-byte row buffers, and with 'half', whose 16-bit codes are decoded, collided in 4 bytes and
!> encoded by dkt_mrt_half. The MRT transform is written out (orthogonal rows, M^-1 = M^T D^-1)
!> rather than a 9x9 product, and the inner loop runs along x so that it vectorises; every node
!> routine is inlined into its loop, with the collision model and the force switch as literals.
!> A uniform body force enters through Guo's forcing term in moment space; a scene without one
!> does not compute it.
module dkt_mrt
  use dkt_kinds, only: wp, sp
  use dkt_lattice, only: w, e3_heat_flux_rate
  use dkt_store, only: lattice_t
  use dkt_mrt_sp, only: collision_sp_t, collision_sp_set, rows_sp, rows_in_place_sp
  use dkt_mrt_half, only: half_sweep_t, half_sweep_init, half_sweep_rows
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
    type(collision_sp_t) :: c4      !! the same in 4 bytes, for lbm.precision = 'single_arith'
  end type collision_t

  !> Row buffers of the in-place sweep, allocated once per run (sweep_init). In-place, row j is
  !! collided while rows j-1 and j+1 are still needed: the populations of old row j-1 that row j
  !! pulls (c_y = +1: 2, 5, 6) are kept in `below`, saved from row j as the loop passes
  !! (into `saved`), and the two populations row j pulls from its own row (c_x = +-1: 1, 3)
  !! are written to `o13` first and stored once the row is done.
  type, public :: sweep_t
    real(wp), allocatable :: below(:, :)      !! (0:nxp-1, 3): old row j-1, populations 2, 5, 6
    real(wp), allocatable :: saved(:, :)      !! the same of old row j, for row j+1
    real(wp), allocatable :: o13(:, :)        !! (0:nxp-1, 2): new populations 1 and 3 of row j
    real(wp), allocatable :: kept_dn(:, :)    !! `below` left by a part, for the part above it
    real(wp), allocatable :: kept_up_d(:, :)  !! (0:nxp-1, 0:8): an old first row of a part,
    real(sp), allocatable :: kept_up_s(:, :)  !! as stored, for the part below it
    real(wp), allocatable :: swap_d(:, :)     !! room for a row while kept_up stands in for it
    real(sp), allocatable :: swap_s(:, :)
    !> below, saved, o13 and kept_dn in 4 bytes, holding deviations, for 'single_arith'
    real(sp), allocatable :: below4(:, :), saved4(:, :), o13_4(:, :), kept_dn4(:, :)
    type(half_sweep_t) :: h !! the row buffers of 'half'
  end type sweep_t

  integer, parameter :: up3(3) = [2, 5, 6] !! the populations with c_y = +1

contains

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
    call collision_sp_set(coll%c4, bgk, coll%s_nu, coll%s_e, coll%s_eps, coll%s_q, force)
  end subroutine collision_init

  !> The nine rates in moment order (rho, e, eps, jx, qx, jy, qy, pxx, pxy).
  pure function collision_describe(coll) result(s)
    type(collision_t), intent(in) :: coll
    real(wp) :: s(0:8)
    s = [0.0_wp, coll%s_e, coll%s_eps, 0.0_wp, coll%s_q, 0.0_wp, coll%s_q, coll%s_nu, coll%s_nu]
  end function collision_describe

  !> Fused pull-stream + collide over rows j1..j2 of a slab, from one 8-byte lattice into
  !! another. Ghost columns 0 and nx+1 and halo rows 0 and nyl+1 of fin must hold what the
  !! boundary rules give (dkt_boundary).
  subroutine stream_collide(coll, fin, fout, nxp, nx, nyl, j1, j2)
    type(collision_t), intent(in) :: coll
    integer, intent(in) :: nxp, nx, nyl          !! padded x extent, columns, slab rows
    real(wp), intent(in) :: fin(0:nxp - 1, 0:nyl + 1, 0:8)
    real(wp), intent(inout) :: fout(0:nxp - 1, 0:nyl + 1, 0:8)
    integer, intent(in) :: j1, j2                !! rows to update
    integer :: j, x
    do j = j1, j2
      if (coll%bgk) then
        if (coll%forced) then
          do concurrent(x=1:nx)
            call node_d(coll, .true., .true., fin, fout, nxp, nyl, x, j)
          end do
        else
          do concurrent(x=1:nx)
            call node_d(coll, .true., .false., fin, fout, nxp, nyl, x, j)
          end do
        end if
      else
        if (coll%forced) then
          do concurrent(x=1:nx)
            call node_d(coll, .false., .true., fin, fout, nxp, nyl, x, j)
          end do
        else
          do concurrent(x=1:nx)
            call node_d(coll, .false., .false., fin, fout, nxp, nyl, x, j)
          end do
        end if
      end if
    end do
  end subroutine stream_collide

  subroutine sweep_init(ws, nxp)
    type(sweep_t), intent(out) :: ws
    integer, intent(in) :: nxp
    allocate (ws%below(0:nxp - 1, 3), ws%saved(0:nxp - 1, 3), ws%o13(0:nxp - 1, 2))
    allocate (ws%kept_dn(0:nxp - 1, 3), ws%kept_up_d(0:nxp - 1, 0:8), ws%kept_up_s(0:nxp - 1, 0:8))
    allocate (ws%swap_d(0:nxp - 1, 0:8), ws%swap_s(0:nxp - 1, 0:8))
    allocate (ws%below4(0:nxp - 1, 3), ws%saved4(0:nxp - 1, 3), ws%o13_4(0:nxp - 1, 2), &
              ws%kept_dn4(0:nxp - 1, 3))
    ws%below4 = 0.0_sp
    ws%saved4 = 0.0_sp
    ws%o13_4 = 0.0_sp
    ws%kept_dn4 = 0.0_sp
    ws%below = 0.0_wp
    ws%saved = 0.0_wp
    ws%o13 = 0.0_wp
    ws%kept_dn = 0.0_wp
    ws%kept_up_d = 0.0_wp
    ws%kept_up_s = 0.0_sp
    call half_sweep_init(ws%h, nxp)
  end subroutine sweep_init

  !> Stream and collide rows j1..j2 from src into dst: two lattices when dst is not src, in
  !! place when it is. Either way, and in 8 or 4 bytes, every node sees the values the
  !! two-lattice sweep gives it, so the results have the same bits (tests/test_mrt.f90).
  !!
  !! The time loop sweeps a slab in parts around the halo exchange (dkt_simulation). In place,
  !! a part overwrites rows its neighbours still pull from: with keep, a part leaves its old first
  !! row (kept_up) and the old populations 2, 5, 6 of its last row (kept_dn) behind, and the part
  !! below takes its row j2+1 from kept_up (above_kept), the part above its row j1-1 from kept_dn
  !! (below_kept).
  subroutine sweep_rows(coll, ws, src, dst, nx, nyl, j1, j2, keep, below_kept, above_kept)
    type(collision_t), intent(in) :: coll
    type(sweep_t), intent(inout) :: ws
    type(lattice_t), intent(in) :: src
    type(lattice_t), intent(inout) :: dst
    integer, intent(in) :: nx, nyl, j1, j2
    logical, intent(in), optional :: keep, below_kept, above_kept
    real(wp) :: sh(0:8)
    real(wp), allocatable :: spare(:, :)
    real(sp), allocatable :: spare4(:, :)
    integer :: j, nxp, k
    if (j2 < j1) return
    if (src%half) then
      call half_sweep_rows(coll%c4, ws%h, src, dst, nx, nyl, j1, j2, opt(keep), opt(below_kept), &
                           opt(above_kept))
      return
    end if
    sh = 0.0_wp
    if (src%shifted) sh = w
    if (src%single) then
      nxp = size(src%s, 1)
      if (.not. associated(src%s, dst%s)) then
        do j = j1, j2
          if (src%arith4) then
            call rows_sp(coll%c4, src%s, dst%s, nxp, nx, nyl, j)
          else
            call rows_s(coll, src%s, dst%s, sh, nxp, nx, nyl, j)
          end if
        end do
        return
      end if
    else
      nxp = size(src%d, 1)
      if (.not. associated(src%d, dst%d)) then
        call stream_collide(coll, src%d, dst%d, nxp, nx, nyl, j1, j2)
        return
      end if
    end if
    ! in place: dst is src
    if (opt(keep)) then
      if (dst%single) then
        ws%kept_up_s = dst%s(:, j1, :)
      else
        ws%kept_up_d = dst%d(:, j1, :)
      end if
    end if
    if (opt(below_kept)) then
      if (dst%arith4) then
        ws%below4 = ws%kept_dn4
      else
        ws%below = ws%kept_dn
      end if
    else
      do k = 1, 3
        if (dst%arith4) then
          ws%below4(0:nx + 1, k) = dst%s(0:nx + 1, j1 - 1, up3(k))
        else if (dst%single) then
          ws%below(0:nx + 1, k) = real(dst%s(0:nx + 1, j1 - 1, up3(k)), wp) + sh(up3(k))
        else
          ws%below(0:nx + 1, k) = dst%d(0:nx + 1, j1 - 1, up3(k))
        end if
      end do
    end if
    ! the row above the last comes from kept_up: put it in row j2+1 for the last row's sweep
    if (opt(above_kept)) then
      if (dst%single) then
        ws%swap_s = dst%s(:, j2 + 1, :)
        dst%s(:, j2 + 1, :) = ws%kept_up_s
      else
        ws%swap_d = dst%d(:, j2 + 1, :)
        dst%d(:, j2 + 1, :) = ws%kept_up_d
      end if
    end if
    do j = j1, j2
      if (dst%arith4) then
        call rows_in_place_sp(coll%c4, dst%s, ws%below4, ws%saved4, ws%o13_4, nxp, nx, nyl, j)
        call move_alloc(ws%below4, spare4)
        call move_alloc(ws%saved4, ws%below4)
        call move_alloc(spare4, ws%saved4)
        cycle
      end if
      if (dst%single) then
        call rows_in_place_s(coll, dst%s, ws, sh, nxp, nx, nyl, j)
      else
        call rows_in_place_d(coll, dst%d, ws, nxp, nx, nyl, j)
      end if
      ! old row j's populations 2, 5, 6 are the next row's below: swap the buffers, not copy
      call move_alloc(ws%below, spare)
      call move_alloc(ws%saved, ws%below)
      call move_alloc(spare, ws%saved)
    end do
    if (opt(above_kept)) then
      if (dst%single) then
        dst%s(:, j2 + 1, :) = ws%swap_s
      else
        dst%d(:, j2 + 1, :) = ws%swap_d
      end if
    end if
    if (opt(keep)) then
      if (dst%arith4) then
        ws%kept_dn4 = ws%below4
      else
        ws%kept_dn = ws%below
      end if
    end if
  contains
    pure logical function opt(flag)
      logical, intent(in), optional :: flag
      opt = .false.
      if (present(flag)) opt = flag
    end function opt
  end subroutine sweep_rows

  !> Row j in place, 8 bytes; leaves old row j's populations 2, 5, 6 in ws%saved.
  subroutine rows_in_place_d(coll, f, ws, nxp, nx, nyl, j)
    type(collision_t), intent(in) :: coll
    integer, intent(in) :: nxp, nx, nyl, j
    real(wp), intent(inout) :: f(0:nxp - 1, 0:nyl + 1, 0:8)
    type(sweep_t), intent(inout) :: ws
    integer :: x, k
    if (coll%bgk) then
      if (coll%forced) then
        do concurrent(x=1:nx)
          call node_in_place_d(coll, .true., .true., f, ws%below, ws%saved, ws%o13, nxp, nyl, x, j)
        end do
      else
        do concurrent(x=1:nx)
          call node_in_place_d(coll, .true., .false., f, ws%below, ws%saved, ws%o13, nxp, nyl, &
                               x, j)
        end do
      end if
    else
      if (coll%forced) then
        do concurrent(x=1:nx)
          call node_in_place_d(coll, .false., .true., f, ws%below, ws%saved, ws%o13, nxp, nyl, &
                               x, j)
        end do
      else
        do concurrent(x=1:nx)
          call node_in_place_d(coll, .false., .false., f, ws%below, ws%saved, ws%o13, nxp, nyl, &
                               x, j)
        end do
      end if
    end if
    f(1:nx, j, 1) = ws%o13(1:nx, 1)
    f(1:nx, j, 3) = ws%o13(1:nx, 2)
    do k = 1, 3
      ws%saved(0, k) = f(0, j, up3(k))
      ws%saved(nx + 1, k) = f(nx + 1, j, up3(k))
    end do
  end subroutine rows_in_place_d

  !> Row j in place, 4 bytes (stored values shifted by sh); the same as rows_in_place_d.
  subroutine rows_in_place_s(coll, f, ws, sh, nxp, nx, nyl, j)
    type(collision_t), intent(in) :: coll
    integer, intent(in) :: nxp, nx, nyl, j
    real(sp), intent(inout) :: f(0:nxp - 1, 0:nyl + 1, 0:8)
    type(sweep_t), intent(inout) :: ws
    real(wp), intent(in) :: sh(0:8)
    integer :: x, k
    if (coll%bgk) then
      if (coll%forced) then
        do concurrent(x=1:nx)
          call node_in_place_s(coll, .true., .true., f, ws%below, ws%saved, ws%o13, sh, nxp, &
                               nyl, x, j)
        end do
      else
        do concurrent(x=1:nx)
          call node_in_place_s(coll, .true., .false., f, ws%below, ws%saved, ws%o13, sh, nxp, &
                               nyl, x, j)
        end do
      end if
    else
      if (coll%forced) then
        do concurrent(x=1:nx)
          call node_in_place_s(coll, .false., .true., f, ws%below, ws%saved, ws%o13, sh, nxp, &
                               nyl, x, j)
        end do
      else
        do concurrent(x=1:nx)
          call node_in_place_s(coll, .false., .false., f, ws%below, ws%saved, ws%o13, sh, nxp, &
                               nyl, x, j)
        end do
      end if
    end if
    f(1:nx, j, 1) = real(ws%o13(1:nx, 1) - sh(1), sp)
    f(1:nx, j, 3) = real(ws%o13(1:nx, 2) - sh(3), sp)
    do k = 1, 3
      ws%saved(0, k) = real(f(0, j, up3(k)), wp) + sh(up3(k))
      ws%saved(nx + 1, k) = real(f(nx + 1, j, up3(k)), wp) + sh(up3(k))
    end do
  end subroutine rows_in_place_s

  !> Row j from one 4-byte lattice into another.
  subroutine rows_s(coll, fin, fout, sh, nxp, nx, nyl, j)
    type(collision_t), intent(in) :: coll
    integer, intent(in) :: nxp, nx, nyl, j
    real(sp), intent(in) :: fin(0:nxp - 1, 0:nyl + 1, 0:8)
    real(sp), intent(inout) :: fout(0:nxp - 1, 0:nyl + 1, 0:8)
    real(wp), intent(in) :: sh(0:8)
    integer :: x
    if (coll%bgk) then
      if (coll%forced) then
        do concurrent(x=1:nx)
          call node_s(coll, .true., .true., fin, fout, sh, nxp, nyl, x, j)
        end do
      else
        do concurrent(x=1:nx)
          call node_s(coll, .true., .false., fin, fout, sh, nxp, nyl, x, j)
        end do
      end if
    else
      if (coll%forced) then
        do concurrent(x=1:nx)
          call node_s(coll, .false., .true., fin, fout, sh, nxp, nyl, x, j)
        end do
      else
        do concurrent(x=1:nx)
          call node_s(coll, .false., .false., fin, fout, sh, nxp, nyl, x, j)
        end do
      end if
    end if
  end subroutine rows_s

  !> Two lattices, 8 bytes: pull into node (x, j) of fin, collide, store in fout.
  pure subroutine node_d(coll, bgk, forced, fin, fout, nxp, nyl, x, j)
    type(collision_t), intent(in) :: coll
    logical, intent(in) :: bgk, forced
    integer, intent(in) :: nxp, nyl, x, j
    real(wp), intent(in) :: fin(0:nxp - 1, 0:nyl + 1, 0:8)
    real(wp), intent(inout) :: fout(0:nxp - 1, 0:nyl + 1, 0:8)
    real(wp) :: f0, f1, f2, f3, f4, f5, f6, f7, f8
    f0 = fin(x, j, 0)
    f1 = fin(x - 1, j, 1)
    f2 = fin(x, j - 1, 2)
    f3 = fin(x + 1, j, 3)
    f4 = fin(x, j + 1, 4)
    f5 = fin(x - 1, j - 1, 5)
    f6 = fin(x + 1, j - 1, 6)
    f7 = fin(x + 1, j + 1, 7)
    f8 = fin(x - 1, j + 1, 8)
    call collide(coll, bgk, forced, f0, f1, f2, f3, f4, f5, f6, f7, f8)
    fout(x, j, 0) = f0
    fout(x, j, 1) = f1
    fout(x, j, 2) = f2
    fout(x, j, 3) = f3
    fout(x, j, 4) = f4
    fout(x, j, 5) = f5
    fout(x, j, 6) = f6
    fout(x, j, 7) = f7
    fout(x, j, 8) = f8
  end subroutine node_d

  !> Two lattices, 4 bytes: the stored values plus sh are the populations.
  pure subroutine node_s(coll, bgk, forced, fin, fout, sh, nxp, nyl, x, j)
    type(collision_t), intent(in) :: coll
    logical, intent(in) :: bgk, forced
    integer, intent(in) :: nxp, nyl, x, j
    real(sp), intent(in) :: fin(0:nxp - 1, 0:nyl + 1, 0:8)
    real(sp), intent(inout) :: fout(0:nxp - 1, 0:nyl + 1, 0:8)
    real(wp), intent(in) :: sh(0:8)
    real(wp) :: f0, f1, f2, f3, f4, f5, f6, f7, f8
    f0 = real(fin(x, j, 0), wp) + sh(0)
    f1 = real(fin(x - 1, j, 1), wp) + sh(1)
    f2 = real(fin(x, j - 1, 2), wp) + sh(2)
    f3 = real(fin(x + 1, j, 3), wp) + sh(3)
    f4 = real(fin(x, j + 1, 4), wp) + sh(4)
    f5 = real(fin(x - 1, j - 1, 5), wp) + sh(5)
    f6 = real(fin(x + 1, j - 1, 6), wp) + sh(6)
    f7 = real(fin(x + 1, j + 1, 7), wp) + sh(7)
    f8 = real(fin(x - 1, j + 1, 8), wp) + sh(8)
    call collide(coll, bgk, forced, f0, f1, f2, f3, f4, f5, f6, f7, f8)
    fout(x, j, 0) = real(f0 - sh(0), sp)
    fout(x, j, 1) = real(f1 - sh(1), sp)
    fout(x, j, 2) = real(f2 - sh(2), sp)
    fout(x, j, 3) = real(f3 - sh(3), sp)
    fout(x, j, 4) = real(f4 - sh(4), sp)
    fout(x, j, 5) = real(f5 - sh(5), sp)
    fout(x, j, 6) = real(f6 - sh(6), sp)
    fout(x, j, 7) = real(f7 - sh(7), sp)
    fout(x, j, 8) = real(f8 - sh(8), sp)
  end subroutine node_s

  !> In place, 8 bytes, node (x, j): the populations of row j-1 come from below, old row j's
  !! 2, 5, 6 go to saved before the node overwrites them, and its new 1 and 3 to o13 (the
  !! neighbours in the row still pull the old ones). No two nodes of a row write the same
  !! entry, and none reads an entry another node of the row writes.
  pure subroutine node_in_place_d(coll, bgk, forced, f, below, saved, o13, nxp, nyl, x, j)
    type(collision_t), intent(in) :: coll
    logical, intent(in) :: bgk, forced
    integer, intent(in) :: nxp, nyl, x, j
    real(wp), intent(inout) :: f(0:nxp - 1, 0:nyl + 1, 0:8)
    real(wp), intent(in) :: below(0:nxp - 1, 3)
    real(wp), intent(inout) :: saved(0:nxp - 1, 3), o13(0:nxp - 1, 2)
    real(wp) :: f0, f1, f2, f3, f4, f5, f6, f7, f8
    f0 = f(x, j, 0)
    f1 = f(x - 1, j, 1)
    f2 = below(x, 1)
    f3 = f(x + 1, j, 3)
    f4 = f(x, j + 1, 4)
    f5 = below(x - 1, 2)
    f6 = below(x + 1, 3)
    f7 = f(x + 1, j + 1, 7)
    f8 = f(x - 1, j + 1, 8)
    saved(x, 1) = f(x, j, 2)
    saved(x, 2) = f(x, j, 5)
    saved(x, 3) = f(x, j, 6)
    call collide(coll, bgk, forced, f0, f1, f2, f3, f4, f5, f6, f7, f8)
    f(x, j, 0) = f0
    o13(x, 1) = f1
    f(x, j, 2) = f2
    o13(x, 2) = f3
    f(x, j, 4) = f4
    f(x, j, 5) = f5
    f(x, j, 6) = f6
    f(x, j, 7) = f7
    f(x, j, 8) = f8
  end subroutine node_in_place_d

  !> In place, 4 bytes: node_in_place_d with the stored values plus sh as the populations.
  pure subroutine node_in_place_s(coll, bgk, forced, f, below, saved, o13, sh, nxp, nyl, x, j)
    type(collision_t), intent(in) :: coll
    logical, intent(in) :: bgk, forced
    integer, intent(in) :: nxp, nyl, x, j
    real(sp), intent(inout) :: f(0:nxp - 1, 0:nyl + 1, 0:8)
    real(wp), intent(in) :: below(0:nxp - 1, 3), sh(0:8)
    real(wp), intent(inout) :: saved(0:nxp - 1, 3), o13(0:nxp - 1, 2)
    real(wp) :: f0, f1, f2, f3, f4, f5, f6, f7, f8
    f0 = real(f(x, j, 0), wp) + sh(0)
    f1 = real(f(x - 1, j, 1), wp) + sh(1)
    f2 = below(x, 1)
    f3 = real(f(x + 1, j, 3), wp) + sh(3)
    f4 = real(f(x, j + 1, 4), wp) + sh(4)
    f5 = below(x - 1, 2)
    f6 = below(x + 1, 3)
    f7 = real(f(x + 1, j + 1, 7), wp) + sh(7)
    f8 = real(f(x - 1, j + 1, 8), wp) + sh(8)
    saved(x, 1) = real(f(x, j, 2), wp) + sh(2)
    saved(x, 2) = real(f(x, j, 5), wp) + sh(5)
    saved(x, 3) = real(f(x, j, 6), wp) + sh(6)
    call collide(coll, bgk, forced, f0, f1, f2, f3, f4, f5, f6, f7, f8)
    f(x, j, 0) = real(f0 - sh(0), sp)
    o13(x, 1) = f1
    f(x, j, 2) = real(f2 - sh(2), sp)
    o13(x, 2) = f3
    f(x, j, 4) = real(f4 - sh(4), sp)
    f(x, j, 5) = real(f5 - sh(5), sp)
    f(x, j, 6) = real(f6 - sh(6), sp)
    f(x, j, 7) = real(f7 - sh(7), sp)
    f(x, j, 8) = real(f8 - sh(8), sp)
  end subroutine node_in_place_s

  !> E1 (MRT) or E4 (BGK) at one node.
  pure subroutine collide(coll, bgk, forced, f0, f1, f2, f3, f4, f5, f6, f7, f8)
    type(collision_t), intent(in) :: coll
    logical, intent(in) :: bgk, forced
    real(wp), intent(inout) :: f0, f1, f2, f3, f4, f5, f6, f7, f8
    if (bgk) then
      call bgk_collide(coll, forced, f0, f1, f2, f3, f4, f5, f6, f7, f8)
    else
      call mrt_collide(coll, forced, f0, f1, f2, f3, f4, f5, f6, f7, f8)
    end if
  end subroutine collide

  pure subroutine mrt_collide(coll, forced, f0, f1, f2, f3, f4, f5, f6, f7, f8)
    type(collision_t), intent(in) :: coll
    logical, intent(in) :: forced !! include the body-force terms
    !> in: the populations pulled into the node; out: post-collision
    real(wp), intent(inout) :: f0, f1, f2, f3, f4, f5, f6, f7, f8
    real(wp) :: rho, rinv, me, meps, jx, qx, jy, qy, pxx, pxy, ux, uy, usq, ruf
    real(wp) :: a, b, c, g, p, r, s, t1, t5, gx1, gx5, gy1, gy5
    real(wp) :: ke, keps, kq, knu
    real(wp) :: g0, g1, g2, g3, g4, g5, g6, g7, g8

    ! rates scaled by the row norms of M, so the relaxed moments come out as the
    ! coefficients of M^-1 = M^T D^-1 directly
    ke = coll%s_e/36.0_wp
    keps = coll%s_eps/36.0_wp
    kq = coll%s_q/12.0_wp
    knu = coll%s_nu/4.0_wp

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
    g0 = f0 - 4.0_wp*(b - c)
    g1 = f1 + t1 + gx1 + r
    g2 = f2 + t1 + gy1 - r
    g3 = f3 + t1 - gx1 + r
    g4 = f4 + t1 - gy1 - r
    g5 = f5 + t5 + gx5 + gy5 + s
    g6 = f6 + t5 - gx5 + gy5 - s
    g7 = f7 + t5 - gx5 - gy5 + s
    g8 = f8 + t5 + gx5 - gy5 - s
    f0 = g0; f1 = g1; f2 = g2; f3 = g3; f4 = g4; f5 = g5; f6 = g6; f7 = g7; f8 = g8
  end subroutine mrt_collide

  pure subroutine bgk_collide(coll, forced, f0, f1, f2, f3, f4, f5, f6, f7, f8)
    type(collision_t), intent(in) :: coll
    logical, intent(in) :: forced !! include the body-force terms
    !> in: the populations pulled into the node; out: post-collision
    real(wp), intent(inout) :: f0, f1, f2, f3, f4, f5, f6, f7, f8
    real(wp) :: rho, rinv, ux, uy, usq, om, cf, fx, fy, base, rw1, rw5, eu, euf, ruf
    real(wp) :: g0, g1, g2, g3, g4, g5, g6, g7, g8
    real(wp), parameter :: w0 = 4.0_wp/9.0_wp, w1 = 1.0_wp/9.0_wp, w5 = 1.0_wp/36.0_wp

    om = coll%s_nu
    fx = coll%force(1); fy = coll%force(2)
    cf = 1.0_wp - 0.5_wp*om

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
    g0 = f0 - om*(f0 - w0*rho*base)
    g1 = f1 - (om*f1 - rw1*(base + 3.0_wp*ux + 4.5_wp*ux*ux))
    g2 = f2 - (om*f2 - rw1*(base + 3.0_wp*uy + 4.5_wp*uy*uy))
    g3 = f3 - (om*f3 - rw1*(base - 3.0_wp*ux + 4.5_wp*ux*ux))
    g4 = f4 - (om*f4 - rw1*(base - 3.0_wp*uy + 4.5_wp*uy*uy))
    eu = ux + uy
    g5 = f5 - (om*f5 - rw5*(base + 3.0_wp*eu + 4.5_wp*eu*eu))
    g7 = f7 - (om*f7 - rw5*(base - 3.0_wp*eu + 4.5_wp*eu*eu))
    eu = uy - ux
    g6 = f6 - (om*f6 - rw5*(base + 3.0_wp*eu + 4.5_wp*eu*eu))
    g8 = f8 - (om*f8 - rw5*(base - 3.0_wp*eu + 4.5_wp*eu*eu))
    if (forced) then
      ! Guo: F_i = w_i [3 (e_i - u).F + 9 (e_i.u)(e_i.F)]
      ruf = ux*fx + uy*fy
      g0 = g0 + cf*w0*(-3.0_wp*ruf)
      g1 = g1 + cf*w1*(3.0_wp*(fx - ruf) + 9.0_wp*ux*fx)
      g2 = g2 + cf*w1*(3.0_wp*(fy - ruf) + 9.0_wp*uy*fy)
      g3 = g3 + cf*w1*(3.0_wp*(-fx - ruf) + 9.0_wp*ux*fx)
      g4 = g4 + cf*w1*(3.0_wp*(-fy - ruf) + 9.0_wp*uy*fy)
      eu = ux + uy
      euf = fx + fy
      g5 = g5 + cf*w5*(3.0_wp*(euf - ruf) + 9.0_wp*eu*euf)
      g7 = g7 + cf*w5*(3.0_wp*(-euf - ruf) + 9.0_wp*eu*euf)
      eu = uy - ux
      euf = fy - fx
      g6 = g6 + cf*w5*(3.0_wp*(euf - ruf) + 9.0_wp*eu*euf)
      g8 = g8 + cf*w5*(3.0_wp*(-euf - ruf) + 9.0_wp*eu*euf)
    end if
    f0 = g0; f1 = g1; f2 = g2; f3 = g3; f4 = g4; f5 = g5; f6 = g6; f7 = g7; f8 = g8
  end subroutine bgk_collide

end module dkt_mrt

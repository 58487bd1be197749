!> Unit tests of the lattice and the collision kernel (docs/model.md E1–E4):
!>  - the E1 moment matrix times M^T D^-1 is the identity (the written-out inverse is right);
!>  - the moments of f^eq are the E2 equilibria;
!>  - the fused sweep equals pull-streaming plus the 9x9 matrix form of E1 with E3 rates,
!>    without and with a body force (Guo's term taken in velocity space and transformed);
!>  - MRT with all rates equal to 1/tau gives the BGK sweep (E4) to round-off;
!>  - the row-by-row sweep (sweep_rows) gives the bits of the two-lattice sweep, from one lattice
!>    into another and in place, whole or split in the three parts the time loop uses around the
!>    halo exchange (rows 3..nyl-2 keeping their end rows, then 1..2 and nyl-1..nyl);
!>  - in 4-byte storage the sweep is the 8-byte sweep of the stored values with only the result
!>    rounded: shifted storage holds exactly f* - w_i rounded, unshifted exactly f* rounded, and
!>    in place equals two lattices bitwise there too.
program test_mrt
  use dkt_kinds, only: wp
  use dkt_check, only: check, finish
  use dkt_lattice, only: ex, ey, w, opp, moment_matrix, moment_norm, equilibrium
  use dkt_kinds, only: sp
  use dkt_store, only: lattice_t, lattice_allocate
  use dkt_mrt, only: collision_t, collision_init, collision_describe, stream_collide, &
                     e3_heat_flux_rate, sweep_t, sweep_init, sweep_rows
  implicit none
  integer, parameter :: nx = 7, nyl = 5, nxp = nx + 2

  call test_inverse()
  call test_equilibrium_moments()
  call test_sweep_matches_matrix(.false.)
  call test_sweep_matches_matrix(.true.)
  call test_mrt_equal_rates_is_bgk(.false.)
  call test_mrt_equal_rates_is_bgk(.true.)
  call test_opposites()
  call test_row_sweep_bits(.false., .false.)
  call test_row_sweep_bits(.false., .true.)
  call test_row_sweep_bits(.true., .false.)
  call test_row_sweep_bits(.true., .true.)
  call test_single_storage(.true.)
  call test_single_storage(.false.)

  call finish()

contains

  function minv() result(mi)
    real(wp) :: mi(0:8, 0:8)
    integer :: k
    do k = 0, 8
      mi(:, k) = moment_matrix(k, :)/moment_norm(k)
    end do
  end function minv

  subroutine test_inverse()
    real(wp) :: id(0:8, 0:8), err
    integer :: k
    id = matmul(moment_matrix, minv())
    do k = 0, 8
      id(k, k) = id(k, k) - 1.0_wp
    end do
    err = maxval(abs(id))
    call check('moment matrix times M^T D^-1 is the identity', err < 1.0e-14_wp, err)
  end subroutine test_inverse

  subroutine test_opposites()
    integer :: i
    logical :: ok
    ok = .true.
    do i = 0, 8
      ok = ok .and. ex(opp(i)) == -ex(i) .and. ey(opp(i)) == -ey(i)
    end do
    call check('opp(i) reverses every lattice velocity', ok, 0.0_wp)
  end subroutine test_opposites

  subroutine test_equilibrium_moments()
    real(wp) :: m(0:8), meq(0:8), rho, ux, uy, err
    rho = 1.037_wp; ux = 0.061_wp; uy = -0.043_wp
    m = matmul(moment_matrix, equilibrium(rho, ux, uy))
    meq = e2(rho, ux, uy)
    err = maxval(abs(m - meq))
    call check('moments of f^eq are the E2 equilibria', err < 1.0e-14_wp, err)
  end subroutine test_equilibrium_moments

  !> E2 in moment order (rho, e, eps, jx, qx, jy, qy, pxx, pxy)
  pure function e2(rho, ux, uy) result(meq)
    real(wp), intent(in) :: rho, ux, uy
    real(wp) :: meq(0:8), usq
    usq = ux*ux + uy*uy
    meq = [rho, rho*(-2.0_wp + 3.0_wp*usq), rho*(1.0_wp - 3.0_wp*usq), rho*ux, -rho*ux, rho*uy, &
           -rho*uy, rho*(ux*ux - uy*uy), rho*ux*uy]
  end function e2

  !> A random but positive lattice with periodic ghosts in x and y.
  subroutine random_lattice(f)
    real(wp), intent(out) :: f(0:nxp - 1, 0:nyl + 1, 0:8)
    call random_rows(f, nyl)
    f(:, 0, :) = f(:, nyl, :)
    f(:, nyl + 1, :) = f(:, 1, :)
    f(0, :, :) = f(nx, :, :)
    f(nx + 1, :, :) = f(1, :, :)
  end subroutine random_lattice

  subroutine test_sweep_matches_matrix(forced)
    logical, intent(in) :: forced
    type(collision_t) :: coll
    real(wp) :: fin(0:nxp - 1, 0:nyl + 1, 0:8), fout(0:nxp - 1, 0:nyl + 1, 0:8)
    real(wp) :: fn(0:8), m(0:8), s(0:8), fi(0:8), ref(0:8), force(2), rho, ux, uy, err, eu, ef
    integer :: x, j, i
    force = 0.0_wp
    if (forced) force = [2.0e-4_wp, -3.0e-4_wp]
    s = [0.0_wp, 1.1_wp, 1.25_wp, 0.0_wp, e3_heat_flux_rate(1/0.7_wp), 0.0_wp, &
         e3_heat_flux_rate(1/0.7_wp), 1/0.7_wp, 1/0.7_wp]
    call collision_init(coll, s, .false., force)
    if (any(collision_describe(coll) /= s)) call check('collision keeps the rates', .false., 0.0_wp)
    call random_lattice(fin)
    fout = 0.0_wp
    call stream_collide(coll, fin, fout, nxp, nx, nyl, 1, nyl)
    err = 0.0_wp
    do j = 1, nyl
      do x = 1, nx
        do i = 0, 8
          fn(i) = fin(x - ex(i), j - ey(i), i)
        end do
        m = matmul(moment_matrix, fn)
        rho = m(0)
        ux = (m(3) + 0.5_wp*force(1))/rho
        uy = (m(5) + 0.5_wp*force(2))/rho
        ! Guo's forcing in velocity space, F_i = w_i [3 (e_i - u).F + 9 (e_i.u)(e_i.F)]
        do i = 0, 8
          eu = ex(i)*ux + ey(i)*uy
          ef = ex(i)*force(1) + ey(i)*force(2)
          fi(i) = w(i)*(3.0_wp*(ef - ux*force(1) - uy*force(2)) + 9.0_wp*eu*ef)
        end do
        m = m - s*(m - e2(rho, ux, uy)) + (1.0_wp - 0.5_wp*s)*matmul(moment_matrix, fi)
        ref = matmul(minv(), m)
        err = max(err, maxval(abs(fout(x, j, :) - ref)))
      end do
    end do
    call check('fused sweep equals streaming + matrix MRT'// &
               merge(' with body force', '                ', forced), err < 1.0e-14_wp, err)
  end subroutine test_sweep_matches_matrix

  subroutine test_mrt_equal_rates_is_bgk(forced)
    logical, intent(in) :: forced
    type(collision_t) :: mrt, bgk
    real(wp) :: fin(0:nxp - 1, 0:nyl + 1, 0:8), fa(0:nxp - 1, 0:nyl + 1, 0:8)
    real(wp) :: fb(0:nxp - 1, 0:nyl + 1, 0:8), force(2), err
    real(wp), parameter :: tau = 0.83_wp
    integer :: k
    force = 0.0_wp
    if (forced) force = [1.0e-4_wp, 2.5e-4_wp]
    call collision_init(mrt, [0.0_wp, (1.0_wp/tau, k=1, 8)], .false., force)
    call collision_init(bgk, [0.0_wp, 9.0_wp, 9.0_wp, 0.0_wp, 9.0_wp, 0.0_wp, 9.0_wp, &
                              1.0_wp/tau, 1.0_wp/tau], .true., force)
    call random_lattice(fin)
    fa = 0.0_wp
    fb = 0.0_wp
    call stream_collide(mrt, fin, fa, nxp, nx, nyl, 1, nyl)
    call stream_collide(bgk, fin, fb, nxp, nx, nyl, 1, nyl)
    err = maxval(abs(fa(1:nx, 1:nyl, :) - fb(1:nx, 1:nyl, :)))
    call check('MRT with all rates 1/tau equals BGK'// &
               merge(' with body force', '                ', forced), err < 1.0e-15_wp, err)
  end subroutine test_mrt_equal_rates_is_bgk

  !> A collision with distinct MRT rates or BGK, with or without a body force.
  subroutine some_collision(coll, bgk, forced)
    type(collision_t), intent(out) :: coll
    logical, intent(in) :: bgk, forced
    real(wp) :: force(2), s(0:8)
    force = 0.0_wp
    if (forced) force = [2.0e-4_wp, -3.0e-4_wp]
    s = [0.0_wp, 1.1_wp, 1.25_wp, 0.0_wp, e3_heat_flux_rate(1/0.7_wp), 0.0_wp, &
         e3_heat_flux_rate(1/0.7_wp), 1/0.7_wp, 1/0.7_wp]
    call collision_init(coll, s, bgk, force)
  end subroutine some_collision

  subroutine test_row_sweep_bits(bgk, forced)
    logical, intent(in) :: bgk, forced
    integer, parameter :: ny = 11
    type(collision_t) :: coll
    type(sweep_t) :: ws
    type(lattice_t) :: a, b, c
    real(wp) :: fin(0:nxp - 1, 0:ny + 1, 0:8), ref(0:nxp - 1, 0:ny + 1, 0:8)
    character(len=:), allocatable :: what
    call some_collision(coll, bgk, forced)
    call random_rows(fin, ny)
    ref = 0.0_wp
    call stream_collide(coll, fin, ref, nxp, nx, ny, 1, ny)
    call sweep_init(ws, nxp)
    call lattice_allocate(a, nxp, ny, .false., .false., .false., half=.false.)
    call lattice_allocate(b, nxp, ny, .false., .false., .false., half=.false.)
    call lattice_allocate(c, nxp, ny, .false., .false., .false., half=.false.)
    what = trim(merge('BGK', 'MRT', bgk))
    if (forced) what = what//' with body force'
    ! one lattice into another
    a%d = fin
    call sweep_rows(coll, ws, a, b, nx, ny, 1, ny)
    call check('row sweep into a second lattice has the bits of the two-lattice sweep, '//what, &
               all(b%d(1:nx, 1:ny, :) == ref(1:nx, 1:ny, :)), 0.0_wp)
    ! in place, whole
    a%d = fin
    call sweep_rows(coll, ws, a, a, nx, ny, 1, ny)
    call check('row sweep in place has the bits of the two-lattice sweep, '//what, &
               all(a%d(1:nx, 1:ny, :) == ref(1:nx, 1:ny, :)), 0.0_wp)
    ! in place, in the time loop's three parts (the halo rows arrive between the first and the
    ! rest: they are corrupted until then, to show the first part does not read them)
    c%d = fin
    c%d(:, 0, :) = -1.0_wp
    c%d(:, ny + 1, :) = -1.0_wp
    call sweep_rows(coll, ws, c, c, nx, ny, 3, ny - 2, keep=.true.)
    c%d(:, 0, :) = fin(:, 0, :)
    c%d(:, ny + 1, :) = fin(:, ny + 1, :)
    call sweep_rows(coll, ws, c, c, nx, ny, 1, 2, above_kept=.true.)
    call sweep_rows(coll, ws, c, c, nx, ny, ny - 1, ny, below_kept=.true.)
    call check('row sweep in place in three parts around the halo has the bits, '//what, &
               all(c%d(1:nx, 1:ny, :) == ref(1:nx, 1:ny, :)), 0.0_wp)
  end subroutine test_row_sweep_bits

  subroutine test_single_storage(shifted)
    logical, intent(in) :: shifted
    integer, parameter :: ny = 9
    type(collision_t) :: coll
    type(sweep_t) :: ws
    type(lattice_t) :: a, b
    real(wp) :: fin(0:nxp - 1, 0:ny + 1, 0:8), ref(0:nxp - 1, 0:ny + 1, 0:8), shift(0:8)
    real(sp) :: expect(1:nx, 1:ny, 0:8)
    integer :: i
    character(len=:), allocatable :: what
    call some_collision(coll, .false., .true.)
    call random_rows(fin, ny)
    shift = 0.0_wp
    if (shifted) shift = w
    call sweep_init(ws, nxp)
    call lattice_allocate(a, nxp, ny, .true., shifted, .false., half=.false.)
    call lattice_allocate(b, nxp, ny, .true., shifted, .false., half=.false.)
    ! the stored values, and the 8-byte lattice they stand for
    do i = 0, 8
      a%s(:, :, i) = real(fin(:, :, i) - shift(i), sp)
      fin(:, :, i) = real(a%s(:, :, i), wp) + shift(i)
    end do
    ref = 0.0_wp
    call stream_collide(coll, fin, ref, nxp, nx, ny, 1, ny)
    do i = 0, 8
      expect(:, :, i) = real(ref(1:nx, 1:ny, i) - shift(i), sp)
    end do
    what = trim(merge('shifted  ', 'unshifted', shifted))
    call sweep_rows(coll, ws, a, b, nx, ny, 1, ny)
    call check('4-byte '//what//' storage: the 8-byte sweep, only the result rounded', &
               all(b%s(1:nx, 1:ny, :) == expect), 0.0_wp)
    call sweep_rows(coll, ws, a, a, nx, ny, 3, ny - 2, keep=.true.)
    call sweep_rows(coll, ws, a, a, nx, ny, 1, 2, above_kept=.true.)
    call sweep_rows(coll, ws, a, a, nx, ny, ny - 1, ny, below_kept=.true.)
    call check('4-byte '//what//' storage: in place in three parts equals two lattices', &
               all(a%s(1:nx, 1:ny, :) == b%s(1:nx, 1:ny, :)), 0.0_wp)
  end subroutine test_single_storage

  !> A disturbed equilibrium on rows 1..ny, ghost columns and halo rows included.
  subroutine random_rows(f, ny)
    integer, intent(in) :: ny
    real(wp), intent(out) :: f(0:nxp - 1, 0:ny + 1, 0:8)
    integer :: x, j
    real(wp) :: r(3)
    f = 0.0_wp
    do j = 0, ny + 1
      do x = 0, nx + 1
        call random_number(r)
        f(x, j, :) = equilibrium(1.0_wp + 0.05_wp*(r(1) - 0.5_wp), 0.08_wp*(r(2) - 0.5_wp), &
                                 0.08_wp*(r(3) - 0.5_wp))
        call random_number(r)
        f(x, j, 1:3) = f(x, j, 1:3)*(1.0_wp + 0.02_wp*(r - 0.5_wp))
      end do
    end do
  end subroutine random_rows

end program test_mrt

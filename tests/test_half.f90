!> Unit tests of the 16-bit format of lbm.precision = 'half' (src/dkt_half.f90) and of its sweep:
!>  - every one of the 65536 codes decodes to a value that encodes back to the same code (the
!>    format has no code that is not a number, so there is nothing to except), and decoding is
!>    strictly monotone in the order of the values (-HALF_MAX .. -0, 0 .. HALF_MAX);
!>  - encoding is monotone on a million sorted random values over the whole range, rounds to
!>    within 2^-12 relative error in the normal range and within 2^-26 (half the subnormal
!>    spacing) below it, and rounds the exact midpoint of every pair of neighbouring codes to the
!>    one with the even mantissa: an 8-bit mantissa (bfloat16) or truncation fails these;
!>  - 0 is code 0 and back, and 2, 1e30, infinity and NaN clamp to +-HALF_MAX (never wrap);
!>  - the sweep in 16 bits, in place, whole or in the time loop's three parts around the halo
!>    exchange, has the bits of the two-lattice sweep, and its every code is the encoding of the
!>    4-byte sweep ('single_arith') of the decoded deviations: the 16-bit sweep computes in 4
!>    bytes exactly as 'single_arith' does and rounds only what it stores (so it differs from
!>    it by at most 2^-12 of the largest deviation).
program test_half
  use iso_fortran_env, only: int16, int32
  use dkt_kinds, only: wp, sp
  use dkt_check, only: check, finish
  use dkt_lattice, only: w, equilibrium, e3_heat_flux_rate
  use dkt_half, only: half_encode, half_decode, HALF_MAX, HALF_MIN_NORMAL
  use dkt_store, only: lattice_t, lattice_allocate
  use dkt_mrt, only: collision_t, collision_init, sweep_t, sweep_init, sweep_rows
  use dkt_suspension, only: heap_sort
  implicit none
  integer, parameter :: nx = 13, nxp = nx + 3
  integer :: k

  call test_round_trip_and_order()
  call test_encode_rounding()
  call test_zero_and_clamp()
  do k = 0, 3
    call test_sweep(k >= 2, mod(k, 2) == 1)
  end do
  call finish()

contains

  !> The codes in the order of their values: 0x8000 + 32767 - n for n < 32768 (negative, from
  !! the largest magnitude down to -0), then n - 32768 (0 up to the largest).
  pure integer(int16) function code_at(n) result(c)
    integer, intent(in) :: n
    if (n < 32768) then
      c = int(-1 - n, int16)
    else
      c = int(n - 32768, int16)
    end if
  end function code_at

  !> The place of a code in that order.
  pure integer function rank_of(c) result(n)
    integer(int16), intent(in) :: c
    if (c < 0) then
      n = -1 - int(c)
    else
      n = int(c) + 32768
    end if
  end function rank_of

  subroutine test_round_trip_and_order()
    integer :: n, bad_trip, bad_order
    real(sp) :: v, prev
    integer(int16) :: c
    bad_trip = 0
    bad_order = 0
    prev = -huge(1.0_sp)
    do n = 0, 65535
      c = code_at(n)
      v = half_decode(c)
      if (half_encode(v) /= c) bad_trip = bad_trip + 1
      ! -0 and +0 are the one pair of equal values
      if (.not. (v > prev .or. (n == 32768 .and. v == prev))) bad_order = bad_order + 1
      prev = v
    end do
    call check('encode(decode(c)) = c for all 65536 codes (codes that fail)', bad_trip == 0, &
               real(bad_trip, wp))
    call check('decode is strictly monotone over the codes in value order (steps that fail)', &
               bad_order == 0 .and. half_decode(code_at(0)) == -HALF_MAX .and. &
               half_decode(code_at(65535)) == HALF_MAX, real(bad_order, wp))
  end subroutine test_round_trip_and_order

  subroutine test_encode_rounding()
    integer, parameter :: n = 1000000
    real(sp), allocatable :: x(:)
    real(wp), allocatable :: r(:), xw(:)
    real(wp) :: rel, ab, e
    real(sp) :: lo, hi, mid, back
    integer :: i, bad_order, bad_tie
    integer(int16) :: c, prev
    ! magnitudes 2^-30 .. 2, log-uniform, both signs; sorted
    allocate (r(n), x(n))
    call random_number(r)
    x(:) = real(2.0_wp**(-30.0_wp + 31.0_wp*r), sp)
    call random_number(r)
    x(:) = merge(-x, x, r < 0.5_wp)
    ! ascending (exact in 8 bytes and back)
    xw = real(x, wp)
    call heap_sort(xw)
    x(:) = real(xw, sp)
    bad_order = 0
    rel = 0.0_wp
    ab = 0.0_wp
    prev = code_at(0)
    do i = 1, n
      c = half_encode(x(i))
      if (rank_of(c) < rank_of(prev)) bad_order = bad_order + 1
      prev = c
      if (abs(x(i)) >= 2.0_sp - 2.0_sp**(-12)) cycle
      e = abs(real(half_decode(c), wp) - real(x(i), wp))
      if (abs(x(i)) >= HALF_MIN_NORMAL) then
        rel = max(rel, e/abs(real(x(i), wp)))
      else
        ab = max(ab, e)
      end if
    end do
    call check('encode is monotone on 1e6 sorted values (inversions)', bad_order == 0, &
               real(bad_order, wp))
    call check('relative rounding error <= 2^-12 in the normal range (max, in units of 2^-12)', &
               rel <= 2.0_wp**(-12), rel/2.0_wp**(-12))
    call check('absolute rounding error <= 2^-26 below 2^-14 (max, in units of 2^-26)', &
               ab <= 2.0_wp**(-26) .and. ab > 0.0_wp, ab/2.0_wp**(-26))
    ! exact midpoints of neighbouring positive codes (4-byte reals hold them exactly)
    bad_tie = 0
    do i = 0, 32766
      lo = half_decode(int(i, int16))
      hi = half_decode(int(i + 1, int16))
      mid = 0.5_sp*(lo + hi)
      back = half_decode(half_encode(mid))
      if (back /= merge(lo, hi, mod(i, 2) == 0)) bad_tie = bad_tie + 1
      if (half_decode(half_encode(-mid)) /= -back) bad_tie = bad_tie + 1
    end do
    call check('every midpoint rounds to the even neighbour, both signs (failures)', &
               bad_tie == 0, real(bad_tie, wp))
  end subroutine test_encode_rounding

  subroutine test_zero_and_clamp()
    real(sp) :: big(5), inf
    integer :: bad
    inf = transfer(int(z'7F800000', int32), inf)
    big = [2.0_sp, 1.0e30_sp, inf, huge(1.0_sp), 2.0_sp - 2.0_sp**(-13)]
    call check('0 is code 0 and code 0 is 0', half_encode(0.0_sp) == 0_int16 .and. &
               half_decode(0_int16) == 0.0_sp, 0.0_wp)
    bad = count(half_decode(half_encode(big)) /= HALF_MAX) + &
          count(half_decode(half_encode(-big)) /= -HALF_MAX)
    call check('2, 1e30, infinity, huge clamp to +-HALF_MAX with their sign (failures)', &
               bad == 0, real(bad, wp))
    call check('NaN clamps to a finite code', abs(half_decode(half_encode(nan()))) == HALF_MAX, &
               0.0_wp)
    call check('1 + 2^-11 is a code (11 mantissa bits)', &
               half_decode(half_encode(1.0_sp + 2.0_sp**(-11))) == 1.0_sp + 2.0_sp**(-11), &
               0.0_wp)
  end subroutine test_zero_and_clamp

  function nan() result(v)
    real(sp) :: v
    v = transfer(int(z'7FC00000', int32), v)
  end function nan

  function label(bgk, forced) result(s)
    logical, intent(in) :: bgk, forced
    character(len=:), allocatable :: s
    s = trim(merge('BGK', 'MRT', bgk))
    if (forced) s = s//' with body force'
  end function label

  !> A disturbed equilibrium (density and velocity deviations of order 0.08) stored in 16 bits in
  !! a, and the same deviations, decoded, in the 4-byte lattice s.
  subroutine random_lattices(a, s, ny)
    type(lattice_t), intent(inout) :: a, s
    integer, intent(in) :: ny
    real(wp) :: r(3), q(0:8), fn(0:8)
    integer :: x, j
    do j = 0, ny + 1
      do x = 0, nx + 1
        call random_number(r)
        fn = equilibrium(1.0_wp + 0.05_wp*(r(1) - 0.5_wp), 0.08_wp*(r(2) - 0.5_wp), &
                         0.08_wp*(r(3) - 0.5_wp))
        call random_number(q)
        fn = fn + 0.016_wp*w*(q - 0.5_wp)
        a%h(x, j, :) = half_encode(real(fn - w, sp))
        s%s(x, j, :) = half_decode(a%h(x, j, :))
      end do
    end do
  end subroutine random_lattices

  subroutine test_sweep(bgk, forced)
    logical, intent(in) :: bgk, forced
    integer, parameter :: ny = 11
    type(collision_t) :: coll
    type(sweep_t) :: ws
    type(lattice_t) :: a, b, c, s, t
    real(wp) :: force(2), rates(0:8), err, scale
    force = 0.0_wp
    if (forced) force = [2.0e-4_wp, -3.0e-4_wp]
    rates = [0.0_wp, 1.1_wp, 1.25_wp, 0.0_wp, e3_heat_flux_rate(1/0.7_wp), 0.0_wp, &
             e3_heat_flux_rate(1/0.7_wp), 1/0.7_wp, 1/0.7_wp]
    call collision_init(coll, rates, bgk, force)
    call sweep_init(ws, nxp)
    call lattice_allocate(a, nxp, ny, .false., .false., .false., half=.true.)
    call lattice_allocate(b, nxp, ny, .false., .false., .false., half=.true.)
    call lattice_allocate(c, nxp, ny, .false., .false., .false., half=.true.)
    call lattice_allocate(s, nxp, ny, .true., .true., .true., half=.false.)
    call lattice_allocate(t, nxp, ny, .true., .true., .true., half=.false.)
    call random_lattices(a, s, ny)
    c%h = a%h
    call sweep_rows(coll, ws, a, b, nx, ny, 1, ny)
    call sweep_rows(coll, ws, s, t, nx, ny, 1, ny)
    scale = maxval(abs(real(t%s(1:nx, 1:ny, :), wp)))
    err = maxval(abs(real(half_decode(b%h(1:nx, 1:ny, :)), wp) - &
                     real(t%s(1:nx, 1:ny, :), wp)))/(2.0_wp**(-12)*scale)
    call check('16-bit sweep stores the codes of the 4-byte sweep of the decoded deviations, '// &
               label(bgk, forced), all(b%h(1:nx, 1:ny, :) == half_encode(t%s(1:nx, 1:ny, :))), &
               0.0_wp)
    call check('16-bit sweep differs from the 4-byte sweep by at most 2^-12 max|f* - w| (in '// &
               'those units), '//label(bgk, forced), err <= 1.0_wp .and. err > 0.0_wp, err)
    call sweep_rows(coll, ws, a, a, nx, ny, 1, ny)
    call check('16-bit sweep in place has the bits of two lattices, '//label(bgk, forced), &
               all(a%h(1:nx, 1:ny, :) == b%h(1:nx, 1:ny, :)), 0.0_wp)
    ! the time loop's three parts; the halo rows arrive after the first (corrupted until then)
    a%h = c%h
    c%h(:, 0, :) = -1_int16
    c%h(:, ny + 1, :) = -1_int16
    call sweep_rows(coll, ws, c, c, nx, ny, 3, ny - 2, keep=.true.)
    c%h(:, 0, :) = a%h(:, 0, :)
    c%h(:, ny + 1, :) = a%h(:, ny + 1, :)
    call sweep_rows(coll, ws, c, c, nx, ny, 1, 2, above_kept=.true.)
    call sweep_rows(coll, ws, c, c, nx, ny, ny - 1, ny, below_kept=.true.)
    call check('16-bit sweep in place in three parts around the halo has the bits, '// &
               label(bgk, forced), all(c%h(1:nx, 1:ny, :) == b%h(1:nx, 1:ny, :)), 0.0_wp)
  end subroutine test_sweep

end program test_half

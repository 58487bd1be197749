!> The 16-bit storage format of lbm.precision = 'half' (docs/design.md, "Data layout"): a
!> population's deviation d = f_i - w_i (rho_0 = 1) in 1 sign bit, 4 exponent bits and 11
!> mantissa bits, held in an integer(int16) code because Fortran has no 2-byte real.
!>
!> Layout of a code, bit 15 first: s eeee mmmmmmmmmmm. With the exponent field e and the
!> mantissa field m,
!>
!>     e = 1..15:  d = (-1)^s 2^(e - 15) (1 + m/2048)     (normal: 2^-14 <= |d| < 2)
!>     e = 0:      d = (-1)^s 2^-14 (m/2048)              (subnormal: |d| < 2^-14, spacing 2^-25)
!>
!> so every code is finite (no infinity, no NaN): the largest magnitude is 2 - 2^-11, which a
!> deviation |d| < 1 never reaches, and larger ones, infinities and NaN are clamped to it with
!> their sign, never wrapped. The exponent bias is the power of two of the scale: an IEEE half
!> would spend one bit more on the exponent and reach 65504 where nothing beyond 1 is needed.
!> Zero is code 0 (the rest state); -0 is code -32768 and stays -0. Encoding rounds to the
!> nearest code, ties to the even mantissa, so the relative error of a normal value is at most
!> 2^-12 and the absolute error of a subnormal one at most 2^-26; the codes are monotone in d.
!>
!> Encoding and decoding are branch-free (integer operations on the bits of a 4-byte real, a
!> merge for the subnormal path) so that the loops over a row that call them vectorise (this
!> file is compiled with -fno-trapping-math, CMakeLists.txt, so that the merge stays a select).
!> A 4-byte subnormal is never formed: decoding converts a subnormal code's mantissa to a 4-byte
!> real and lowers its exponent by 25, and encoding turns a subnormal value into an integer code
!> by adding 2^23 to |d| 2^25. Rows are packed and unpacked here, where the two functions inline
!> into the loops.
module dkt_half
  use iso_fortran_env, only: int16, int32
  use dkt_kinds, only: sp
  implicit none
  private
  public :: half_encode, half_decode, half_unpack, half_unpack_row, half_pack_row, &
            HALF_MAX, HALF_MIN_NORMAL

  real(sp), parameter :: HALF_MAX = 2.0_sp - 2.0_sp**(-11)  !! the largest magnitude of a code
  real(sp), parameter :: HALF_MIN_NORMAL = 2.0_sp**(-14)    !! the smallest normal magnitude

  !> Bits of 4-byte reals used by the encoding: 2 (the clamp), 2^-14 (below it, subnormal
  !! codes) and 2^23 (whose last mantissa bit is 1, so that x + 2^23 rounds x to an integer).
  integer(int32), parameter :: BITS_TWO = int(z'40000000', int32)
  integer(int32), parameter :: BITS_MIN_NORMAL = int(z'38800000', int32)
  integer(int32), parameter :: BITS_2P23 = int(z'4B000000', int32)
  integer(int32), parameter :: LARGEST_CODE = 32767 !! e = 15, m = 2047
  !> exponent bias of a 4-byte real less the format's, in the position of a 4-byte real's
  !! exponent field
  integer(int32), parameter :: REBIAS = (127 - 15)*2**23
  integer(int32), parameter :: SIGN_BIT = -huge(1_int32) - 1 !! bit 31 alone

contains

  !> The code nearest to d (ties to the even mantissa), clamped to +-HALF_MAX.
  elemental function half_encode(d) result(code)
    real(sp), intent(in) :: d
    integer(int16) :: code
    integer(int32) :: b, mag, normal, small, c
    b = transfer(d, b)
    ! the magnitude's bits, limited to those of 2 (infinity and NaN too), which clamps below
    mag = min(iand(b, huge(b)), BITS_TWO)
    ! normal: rebias the exponent from 127 to 15 and drop 12 of the 23 mantissa bits, rounding
    ! to even (add 2047 and the lowest kept bit; a carry moves into the exponent, as it should)
    normal = ishft(mag + (2047 - REBIAS) + iand(ishft(mag, -12), 1), -12)
    ! subnormal: |d| 2^25 rounded to an integer, ties to even, by the addition of 2^23 (the
    ! result's last mantissa bit is worth 1); 2048 when it rounds up to the smallest normal
    small = transfer(transfer(mag, d)*2.0_sp**25 + 2.0_sp**23, small) - BITS_2P23
    c = min(merge(small, normal, mag < BITS_MIN_NORMAL), LARGEST_CODE)
    ! the sign bit makes a negative 16-bit integer: bit 15 set is c - 32768
    code = int(c - iand(ishft(b, -16), 32768), int16)
  end function half_encode

  !> The deviation a code holds, exactly, as a 4-byte real.
  elemental function half_decode(code) result(d)
    integer(int16), intent(in) :: code
    real(sp) :: d
    integer(int32) :: c, mag, bits, small
    c = int(code, int32)
    mag = iand(c, LARGEST_CODE)
    ! normal: the exponent and mantissa fields moved into a 4-byte real's, rebiased
    bits = ishft(mag, 12) + REBIAS
    ! subnormal (exponent field 0): the mantissa as a 4-byte real, times 2^-25 by lowering its
    ! exponent (exact; code 0 gives 0 through the max). The choice is made on the bits, so
    ! that it is a select, not a branch, and no subnormal 4-byte real is ever formed.
    small = max(transfer(real(mag, sp), c) - 25*2**23, 0)
    bits = merge(small, bits, mag < 2048)
    ! the sign: bit 31 of the code extended to 4 bytes
    d = transfer(ior(bits, iand(c, SIGN_BIT)), d)
  end function half_decode

  !> What row j of the sweep reads, decoded for columns lo..hi in one pass over the nine
  !! planes (nine streams at once, as the 4-byte sweep reads them, so that the hardware
  !! prefetches them together): populations 0, 1, 3 of row j and 4, 7, 8 of row j+1 into
  !! pulled(:, i), and 2, 5, 6 of row j into up(:, 1:3).
  subroutine half_unpack_row(h, nxp, nyl, j, lo, hi, pulled, up)
    integer, intent(in) :: nxp, nyl, j, lo, hi
    integer(int16), intent(in) :: h(0:nxp - 1, 0:nyl + 1, 0:8)
    real(sp), intent(inout) :: pulled(0:nxp - 1, 0:8), up(0:nxp - 1, 3)
    integer :: x
    do concurrent(x=lo:hi)
      pulled(x, 0) = half_decode(h(x, j, 0))
      pulled(x, 1) = half_decode(h(x, j, 1))
      up(x, 1) = half_decode(h(x, j, 2))
      pulled(x, 3) = half_decode(h(x, j, 3))
      up(x, 2) = half_decode(h(x, j, 5))
      up(x, 3) = half_decode(h(x, j, 6))
      pulled(x, 4) = half_decode(h(x, j + 1, 4))
      pulled(x, 7) = half_decode(h(x, j + 1, 7))
      pulled(x, 8) = half_decode(h(x, j + 1, 8))
    end do
  end subroutine half_unpack_row

  !> h(lo:hi, j, 0:8) = the codes of the nine deviations v(lo:hi, 0:8), in one pass.
  subroutine half_pack_row(v, h, nxp, nyl, j, lo, hi)
    integer, intent(in) :: nxp, nyl, j, lo, hi
    real(sp), intent(in) :: v(0:nxp - 1, 0:8)
    integer(int16), intent(inout) :: h(0:nxp - 1, 0:nyl + 1, 0:8)
    integer :: x
    do concurrent(x=lo:hi)
      h(x, j, 0) = half_encode(v(x, 0))
      h(x, j, 1) = half_encode(v(x, 1))
      h(x, j, 2) = half_encode(v(x, 2))
      h(x, j, 3) = half_encode(v(x, 3))
      h(x, j, 4) = half_encode(v(x, 4))
      h(x, j, 5) = half_encode(v(x, 5))
      h(x, j, 6) = half_encode(v(x, 6))
      h(x, j, 7) = half_encode(v(x, 7))
      h(x, j, 8) = half_encode(v(x, 8))
    end do
  end subroutine half_pack_row

  !> v(lo:hi) = the deviations of codes h(lo:hi, j, i).
  pure subroutine half_unpack(h, nxp, nyl, j, i, lo, hi, v)
    integer, intent(in) :: nxp, nyl, j, i, lo, hi
    integer(int16), intent(in) :: h(0:nxp - 1, 0:nyl + 1, 0:8)
    real(sp), intent(inout) :: v(0:nxp - 1)
    integer :: x
    do concurrent(x=lo:hi)
      v(x) = half_decode(h(x, j, i))
    end do
  end subroutine half_unpack

end module dkt_half

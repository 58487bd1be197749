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
!> merge for the subnormal path) so that the loops over a row that call them vectorise. A 4-byte
!> subnormal is never formed: decoding scales an integer mantissa by a power of two no smaller
!> than 2^-25, and encoding turns a subnormal code into an integer by adding 2^23 to d 2^25.
!> Rows are packed and unpacked here, where the two functions inline into the loops.
module dkt_half
  use iso_fortran_env, only: int16, int32
  use dkt_kinds, only: sp
  implicit none
  private
  public :: half_encode, half_decode, half_unpack, half_pack, HALF_MAX, HALF_MIN_NORMAL

  real(sp), parameter :: HALF_MAX = 2.0_sp - 2.0_sp**(-11)  !! the largest magnitude of a code
  real(sp), parameter :: HALF_MIN_NORMAL = 2.0_sp**(-14)    !! the smallest normal magnitude

  !> Bits of 4-byte reals used by the encoding: 2 (the clamp), 2^-14 (below it, subnormal
  !! codes) and 2^23 (whose last mantissa bit is 1, so that x + 2^23 rounds x to an integer).
  integer(int32), parameter :: BITS_TWO = int(z'40000000', int32)
  integer(int32), parameter :: BITS_MIN_NORMAL = int(z'38800000', int32)
  integer(int32), parameter :: BITS_2P23 = int(z'4B000000', int32)
  integer(int32), parameter :: LARGEST_CODE = 32767 !! e = 15, m = 2047
  !> exponent bias of a 4-byte real less the format's, in the position of the exponent field
  integer(int32), parameter :: REBIAS = (127 - 15)*2048

contains

  !> The code nearest to d (ties to the even mantissa), clamped to +-HALF_MAX.
  elemental function half_encode(d) result(code)
    real(sp), intent(in) :: d
    integer(int16) :: code
    integer(int32) :: b, mag, sgn, normal, small, c
    real(sp) :: a
    b = transfer(d, b)
    sgn = ishft(b, -31)
    ! the magnitude's bits, limited to those of 2 (infinity and NaN too), which clamps below
    mag = min(iand(b, huge(b)), BITS_TWO)
    ! normal: drop 12 of the 23 mantissa bits rounding to even (a carry moves into the
    ! exponent, as it should), then rebias the exponent from 127 to 15
    normal = ishft(mag + 2047 + iand(ishft(mag, -12), 1), -12) - REBIAS
    ! subnormal: |d| 2^25 rounded to an integer, ties to even, by the addition of 2^23 (the
    ! result's last mantissa bit is worth 1); 2048 when it rounds up to the smallest normal
    a = transfer(mag, a)
    small = transfer(a*2.0_sp**25 + 2.0_sp**23, small) - BITS_2P23
    c = min(merge(small, normal, mag < BITS_MIN_NORMAL), LARGEST_CODE)
    ! the sign bit makes a negative 16-bit integer: bit 15 set is c - 32768
    code = int(c - sgn*32768, int16)
  end function half_encode

  !> The deviation a code holds, exactly, as a 4-byte real.
  elemental function half_decode(code) result(d)
    integer(int16), intent(in) :: code
    real(sp) :: d
    integer(int32) :: u, e, m, normal
    u = iand(int(code, int32), 65535)
    e = ishft(iand(u, 30720), -11)
    m = iand(u, 2047)
    ! the hidden bit of a normal code; a subnormal one scales like exponent field 1
    normal = min(e, 1)
    d = real(m + normal*2048, sp)*transfer(ishft(e + 1 - normal - 26 + 127, 23), d)
    d = merge(-d, d, code < 0)
  end function half_decode

  !> v(lo:hi) = the deviations of codes h(lo:hi, j, i).
  subroutine half_unpack(h, nxp, nyl, j, i, lo, hi, v)
    integer, intent(in) :: nxp, nyl, j, i, lo, hi
    integer(int16), intent(in) :: h(0:nxp - 1, 0:nyl + 1, 0:8)
    real(sp), intent(inout) :: v(0:nxp - 1)
    integer :: x
    do concurrent(x=lo:hi)
      v(x) = half_decode(h(x, j, i))
    end do
  end subroutine half_unpack

  !> h(lo:hi, j, i) = the codes of deviations v(lo:hi).
  subroutine half_pack(v, h, nxp, nyl, j, i, lo, hi)
    integer, intent(in) :: nxp, nyl, j, i, lo, hi
    real(sp), intent(in) :: v(0:nxp - 1)
    integer(int16), intent(inout) :: h(0:nxp - 1, 0:nyl + 1, 0:8)
    integer :: x
    do concurrent(x=lo:hi)
      h(x, j, i) = half_encode(v(x))
    end do
  end subroutine half_pack

end module dkt_half

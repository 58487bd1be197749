!> Text helpers every layer may use: integers and reals as text (reals round-trip exactly),
!> quoting, printable forms of user bytes, plurals, lower case and a linear text builder. The
!> bottom layer beside dkt_kinds: it uses nothing of the solver or the input.
module dkt_text
  use, intrinsic :: ieee_arithmetic, only: ieee_is_finite
  use, intrinsic :: ieee_exceptions, only: ieee_status_type, ieee_get_status, ieee_set_status
  use, intrinsic :: ieee_exceptions, only: ieee_set_halting_mode, ieee_usual
  use, intrinsic :: iso_fortran_env, only: int64
  use dkt_kinds, only: wp
  implicit none
  private
  public :: read_real, fmt_real, fmt_num, quoted, printable, append_text, counted, itoa
  public :: lower_case

contains

  !> Read real `text` (a real as list-directed input writes it) into `x`, with no
  !! floating-point trap: a literal beyond the double range (1e999) gives Infinity and the
  !! reader says it is too large, where a build that traps overflow (-ffpe-trap=overflow) would
  !! otherwise die inside the read. The exception flags and halting modes are restored
  !! afterwards. fmt_real reads its candidate texts back the same way: a short text of the
  !! largest double rounds up beyond it.
  subroutine read_real(text, x, ios)
    character(len=*), intent(in) :: text
    real(wp), intent(out) :: x
    integer, intent(out) :: ios
    type(ieee_status_type) :: status
    call ieee_get_status(status)
    call ieee_set_halting_mode(ieee_usual, .false.)
    read (text, *, iostat=ios) x
    call ieee_set_status(status)
  end subroutine read_real

  !> A computed number in a message: as fmt_real when ten significant digits or fewer give `x`
  !! exactly, else six significant digits (0.25000124999804724 -> 0.250001), so that round-off
  !! tails do not show.
  function fmt_num(x) result(s)
    real(wp), intent(in) :: x
    character(len=:), allocatable :: s
    s = fmt_real(x, short=.true.)
  end function fmt_num

  !> The shortest decimal text that reads back to exactly `x`, with a decimal point or an
  !! exponent so that it reads as a real: 2.0, 0.004, 0.135526, 1.0e-7, -3.5e20. With `short`,
  !! six significant digits when that takes more than ten.
  function fmt_real(x, short) result(s)
    real(wp), intent(in) :: x
    logical, intent(in), optional :: short
    character(len=:), allocatable :: s
    character(len=40) :: buf
    character(len=16) :: fmt
    character(len=:), allocatable :: digits
    integer :: d, e, p, ios
    real(wp) :: y
    if (abs(x) <= 0.0_wp) then
      s = '0.0'
      return
    else if (.not. ieee_is_finite(x)) then
      write (buf, *) x
      s = trim(adjustl(buf))
      return
    end if
    do d = 1, 17
      write (fmt, '(a,i0,a)') '(es40.', d, 'e3)'
      write (buf, fmt) abs(x)
      call read_real(buf, y, ios)
      if (ios == 0 .and. transfer(y, 0_int64) == transfer(abs(x), 0_int64)) exit ! bitwise
    end do
    if (present(short)) then
      if (short .and. d > 9) write (buf, '(es40.5e3)') abs(x)
    end if
    buf = adjustl(buf)
    p = index(buf, 'E')
    read (buf(p + 1:), *) e
    digits = buf(1:1)//buf(3:p - 1) ! mantissa d.ddd without its point
    do while (len(digits) > 1 .and. digits(len(digits):) == '0')
      digits = digits(:len(digits) - 1)
    end do
    if (e >= 0 .and. e < 16) then
      if (len(digits) <= e + 1) then
        s = digits//repeat('0', e + 1 - len(digits))//'.0'
      else
        s = digits(:e + 1)//'.'//digits(e + 2:)
      end if
    else if (e < 0 .and. e >= -4) then
      s = '0.'//repeat('0', -e - 1)//digits
    else if (len(digits) == 1) then
      s = digits//'.0e'//itoa(e)
    else
      s = digits(1:1)//'.'//digits(2:)//'e'//itoa(e)
    end if
    if (x < 0.0_wp) s = '-'//s
  end function fmt_real

  function quoted(s) result(q)
    character(len=*), intent(in) :: s
    character(len=:), allocatable :: q
    integer :: j, n
    allocate (character(len=2*len(s) + 2) :: q)
    n = 1
    q(1:1) = ''''
    do j = 1, len(s)
      n = n + 1
      q(n:n) = s(j:j)
      if (s(j:j) == '''') then ! a quote inside a string is doubled
        n = n + 1
        q(n:n) = ''''
      end if
    end do
    q = q(:n)//''''
  end function quoted

  !> `text` with every byte a terminal would not show as written replaced by its hex code in
  !! angle brackets: control bytes (ESC is <1b>, NUL <00>, DEL <7f>, also tab and line ends)
  !! and bytes that are not part of a valid UTF-8 character (a stray Latin-1 byte). Messages
  !! quote the user's input through it, so that an invisible byte can neither hide in the
  !! message ('tau = 1.0<1b> is not a real number') nor act on the terminal.
  function printable(text) result(s)
    character(len=*), intent(in) :: text
    character(len=:), allocatable :: s
    integer :: j, b, n, m, ns
    character(len=*), parameter :: HEX = '0123456789abcdef'
    ns = 0
    call append_text(s, ns, '')
    j = 1
    do while (j <= len(text))
      b = ichar(text(j:j))
      n = 0 ! the continuation bytes of a UTF-8 character that starts with byte b
      if (b >= 194 .and. b <= 223) n = 1
      if (b >= 224 .and. b <= 239) n = 2
      if (b >= 240 .and. b <= 244) n = 3
      if (n > 0 .and. j + n <= len(text)) then
        do m = 1, n
          if (ichar(text(j + m:j + m)) < 128 .or. ichar(text(j + m:j + m)) > 191) n = 0
        end do
        if (n > 0) then
          call append_text(s, ns, text(j:j + n))
          j = j + n + 1
          cycle
        end if
      end if
      if (b < 32 .or. b >= 127) then
        call append_text(s, ns, '<'//HEX(b/16 + 1:b/16 + 1)// &
                         HEX(mod(b, 16) + 1:mod(b, 16) + 1)//'>')
      else
        call append_text(s, ns, text(j:j))
      end if
      j = j + 1
    end do
    s = s(:ns)
  end function printable

  !> Append `piece` to the first `n` characters of `buf`, doubling its length when it is full,
  !! so that building a text of many pieces takes time linear in its length (`s = s//piece`
  !! copies the whole text each time). The text is buf(:n).
  pure subroutine append_text(buf, n, piece)
    character(len=:), allocatable, intent(inout) :: buf
    integer, intent(inout) :: n
    character(len=*), intent(in) :: piece
    character(len=:), allocatable :: tmp
    if (.not. allocated(buf)) then
      allocate (character(len=max(64, 2*len(piece))) :: buf)
      n = 0
    else if (n + len(piece) > len(buf)) then
      ! copied twice rather than with move_alloc, which gfortran gets wrong for deferred-length
      ! strings (the new length is lost)
      tmp = buf(:n)
      deallocate (buf)
      allocate (character(len=max(2*(n + len(piece)), 64)) :: buf)
      buf(:n) = tmp
    end if
    buf(n + 1:n + len(piece)) = piece
    n = n + len(piece)
  end subroutine append_text

  !> `n` and the noun, plural unless n is 1: '1 rank', '2 ranks'.
  function counted(n, noun) result(s)
    integer, intent(in) :: n
    character(len=*), intent(in) :: noun
    character(len=:), allocatable :: s
    s = itoa(n)//' '//noun
    if (n /= 1) s = s//'s'
  end function counted

  function itoa(i) result(s)
    integer, intent(in) :: i
    character(len=:), allocatable :: s
    character(len=12) :: buf
    write (buf, '(i0)') i
    s = trim(buf)
  end function itoa

  pure function lower_case(s) result(t)
    character(len=*), intent(in) :: s
    character(len=len(s)) :: t
    integer :: j
    t = s
    do j = 1, len(s)
      if (s(j:j) >= 'A' .and. s(j:j) <= 'Z') t(j:j) = achar(iachar(s(j:j)) + 32)
    end do
  end function lower_case

end module dkt_text

!> The tokens of namelist text (dkt_namelist reads them): words, strings, '=', ',', '/', group
!> names, subscripts and, where the text cannot go on, one token that says why, for the parser
!> to report with the group and key around it.
module dkt_namelist_lexer
  use dkt_text, only: lower_case, quoted, itoa
  implicit none
  private
  public :: token_t, tokenize, display, no_blanks, make_token, append, BLANKS
  public :: TOK_WORD, TOK_STRING, TOK_EQ, TOK_COMMA, TOK_END, TOK_GROUP, TOK_NULL, TOK_SUB
  public :: TOK_BAD, BAD_PAREN, BAD_STRING, BAD_AMPERSAND

  integer, parameter :: TOK_WORD = 1, TOK_STRING = 2, TOK_EQ = 3, TOK_COMMA = 4, TOK_END = 5, &
                        TOK_GROUP = 6, TOK_NULL = 7, TOK_SUB = 8, TOK_BAD = 9
  !> What a TOK_BAD is: an index '(' without ')', a string without its closing quote, a '&'
  !! without a group name. The tokenizer stops there and the parser, which knows the group and
  !! the key around it, says what is wrong.
  integer, parameter :: BAD_PAREN = 1, BAD_STRING = 2, BAD_AMPERSAND = 3
  type :: token_t
    integer :: kind = 0
    integer :: line = 0
    character(len=:), allocatable :: text !! a word as written, a string without its quotes,
                                          !! a subscript '(a:b)' without blanks
    character(len=:), allocatable :: rep  !! the 'r' of r*'text' (strings only); unallocated if none
    integer :: bad = 0                    !! TOK_BAD: BAD_PAREN, BAD_STRING or BAD_AMPERSAND
    character(len=:), allocatable :: why  !! TOK_BAD: what else the message says
  end type token_t

  character(len=*), parameter :: BLANKS = ' '//achar(9)//achar(13)//achar(10)

contains

  !> Split `text` into tokens. Lexical errors (an unclosed string, an index '(' without ')',
  !! a bare '&') end the list with a TOK_BAD token, for the parser to report in its context.
  !! A leading UTF-8 byte-order mark is skipped.
  subroutine tokenize(text, toks, nt)
    character(len=*), intent(in) :: text
    type(token_t), allocatable, intent(out) :: toks(:)
    integer, intent(out) :: nt
    character(len=:), allocatable :: s, rep, why
    character(len=:), allocatable :: buf !! the characters of a string token
    character :: c, quote
    integer :: p, q, k, line, n, first_line, last_end, nl, start
    integer :: spanned !! first line of the last string that ran over lines; 0 if none
    logical :: has_rep
    allocate (toks(64))
    nt = 0
    s = ''
    line = 1
    p = 1
    n = len(text)
    last_end = -1 ! where the last token ends, to see whether a string follows r* directly
    spanned = 0
    ! A UTF-8 byte-order mark, as some editors save a file, is not part of the namelist.
    if (n >= 3) then
      if (text(1:3) == char(239)//char(187)//char(191)) p = 4
    end if
    do while (p <= n)
      c = text(p:p)
      if (c == achar(10)) then
        line = line + 1
      else if (index(BLANKS, c) > 0) then
        continue
      else if (c == '!') then
        q = index(text(p:), achar(10))
        if (q == 0) exit
        p = p + q - 2 ! stop before the newline so that it is counted
      else if (c == ',') then
        call push(TOK_COMMA, c)
      else if (c == '=') then
        call push(TOK_EQ, c)
      else if (c == '/') then
        call push(TOK_END, c)
      else if (c == '(') then
        ! An index or section, up to ')' on the same line; blanks inside are dropped.
        q = index(text(p:), ')')
        nl = index(text(p:), achar(10))
        if (q == 0 .or. (nl > 0 .and. nl < q)) then
          call push_bad(BAD_PAREN, trim(text(p:p - 1 + merge(nl - 1, n - p + 1, nl > 0))), '')
          return
        end if
        start = p
        p = p + q - 1
        call push(TOK_SUB, no_blanks(text(start:p)))
      else if (c == '''' .or. c == '"') then
        ! r*'text': a repeat count written right before the quote belongs to the string.
        has_rep = .false.
        if (nt > 0 .and. last_end == p - 1) then
          if (toks(nt)%kind == TOK_WORD) then
            q = len(toks(nt)%text)
            if (toks(nt)%text(q:q) == '*') then
              has_rep = .true.
              rep = toks(nt)%text(:q - 1)
              nt = nt - 1
            end if
          end if
        end if
        ! A string may go on over lines (the line ends are not part of it, F2008 10.11.3.3).
        quote = c
        first_line = line
        ! the string is built in a buffer as long as the text (it cannot be longer), allocated
        ! once, so that the time is linear in the length of the text
        if (.not. allocated(buf)) allocate (character(len=n) :: buf)
        call scan_string(text, quote, p, line, buf, k)
        if (p > n) then
          q = index(buf(:k)//achar(10), achar(10))
          why = 'it ends at the next '//quote//' (a doubled '//quote//quote// &
                ' stands for one), maybe on a later line'
          ! A quote left out earlier makes the next string run on and pair the wrong quotes.
          if (spanned > 0) why = why//'; the string that starts on line '//itoa(spanned)// &
                                 ' runs over several lines: is its closing quote missing?'
          line = first_line
          call push_bad(BAD_STRING, quote//buf(:q - 1), why)
          return
        end if
        line_ends: block
          integer :: j, m
          m = 0
          do j = 1, k
            if (buf(j:j) == achar(10)) cycle
            m = m + 1
            buf(m:m) = buf(j:j)
          end do
          s = buf(:m)
        end block line_ends
        call push(TOK_STRING, s, first_line)
        if (line > first_line) spanned = first_line
        if (has_rep) toks(nt)%rep = rep
      else
        q = p
        do while (q < n)
          if (scan(text(q + 1:q + 1), BLANKS//',=/!''"(') > 0) exit
          q = q + 1
        end do
        start = p
        p = q
        if (c == '&' .or. c == '$') then
          if (q == start) then
            call push_bad(BAD_AMPERSAND, c, '')
            return
          end if
          if (lower_case(text(start + 1:q)) == 'end') then
            call push(TOK_END, text(start:q))
          else
            call push(TOK_GROUP, lower_case(text(start + 1:q)))
          end if
        else
          call push(TOK_WORD, text(start:q))
        end if
      end if
      p = p + 1
    end do
  contains
    subroutine push(kind, word, at_line)
      integer, intent(in) :: kind
      character(len=*), intent(in) :: word
      integer, intent(in), optional :: at_line
      call append(toks, nt, make_token(kind, line, word))
      if (present(at_line)) toks(nt)%line = at_line
      last_end = p ! p is at the last character of the token
    end subroutine push

    !> The token where the text cannot go on (see BAD_PAREN ..); the tokenizer stops after it.
    subroutine push_bad(bad, word, why)
      integer, intent(in) :: bad
      character(len=*), intent(in) :: word, why
      call push(TOK_BAD, word)
      toks(nt)%bad = bad
      toks(nt)%why = why
    end subroutine push_bad
  end subroutine tokenize

  !> The characters of a string whose opening `quote` is at text(p): on return p is at its
  !! closing quote (p > len(text) if there is none), `line` counts the line ends passed, and
  !! buf(:k) holds the string with each line end as achar(10) (a CR before it dropped) and
  !! each doubled quote as one.
  subroutine scan_string(text, quote, p, line, buf, k)
    character(len=*), intent(in) :: text
    character, intent(in) :: quote
    integer, intent(inout) :: p, line
    character(len=*), intent(inout) :: buf
    integer, intent(out) :: k
    integer :: n
    n = len(text)
    k = 0
    do
      p = p + 1
      if (p > n) return
      if (text(p:p) == achar(10)) then
        line = line + 1
        if (k > 0) then ! drop the CR of a CR LF line end
          if (buf(k:k) == achar(13)) k = k - 1
        end if
        k = k + 1
        buf(k:k) = achar(10) ! kept only to cut the message of an unclosed string; then removed
        cycle
      end if
      if (text(p:p) == quote) then
        if (p < n) then
          if (text(p + 1:p + 1) == quote) then ! a doubled quote stands for one
            k = k + 1
            buf(k:k) = quote
            p = p + 1
            cycle
          end if
        end if
        exit
      end if
      k = k + 1
      buf(k:k) = text(p:p)
    end do
  end subroutine scan_string

  subroutine append(list, n, t)
    type(token_t), allocatable, intent(inout) :: list(:)
    integer, intent(inout) :: n
    type(token_t), intent(in) :: t
    type(token_t), allocatable :: tmp(:)
    if (n == size(list)) then
      allocate (tmp(2*n))
      tmp(1:n) = list
      call move_alloc(tmp, list)
    end if
    n = n + 1
    list(n) = t
  end subroutine append

  function make_token(kind, line, text) result(t)
    integer, intent(in) :: kind, line
    character(len=*), intent(in) :: text
    type(token_t) :: t
    t%kind = kind
    t%line = line
    t%text = text
  end function make_token

  !> `text` without its blanks (an index may be written with blanks: x( 1 : 2 )).
  pure function no_blanks(text) result(s)
    character(len=*), intent(in) :: text
    character(len=:), allocatable :: s
    integer :: j
    s = ''
    do j = 1, len(text)
      if (index(BLANKS, text(j:j)) == 0) s = s//text(j:j)
    end do
  end function no_blanks

  !> A token as it was written: a string quoted again, with its repeat count.
  function display(t) result(s)
    type(token_t), intent(in) :: t
    character(len=:), allocatable :: s
    if (t%kind == TOK_STRING) then
      s = quoted(t%text)
      if (allocated(t%rep)) then
        if (len(t%rep) > 0) s = t%rep//'*'//s
      end if
    else
      s = t%text
    end if
  end function display

end module dkt_namelist_lexer

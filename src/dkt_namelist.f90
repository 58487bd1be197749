!> Namelist-style input text read into the keys of a registry (module dkt_registry), with
!> messages that name the file, line, group, key and value of whatever is wrong.
!>
!> The intrinsic `read(nml=)` is not used because its errors name neither the key nor the value,
!> and it cannot suggest a spelling or give line numbers.
!>
!> Accepted text: groups `&name ... /` (or `&end`), items `key = value` separated by commas,
!> blanks or newlines, array elements `key(2) = v` and lists `key = v1, v2` (an empty item
!> between commas leaves that element unchanged), strings in '..' or ".." (doubled quote
!> inside), logicals .true./.false./T/F/true/false, `!` comments outside strings; names are
!> case-insensitive. A key given twice keeps the last value. Values are converted and stored
!> here; ranges and choices are checked later (check_key), after every override.
module dkt_namelist
  use, intrinsic :: ieee_arithmetic, only: ieee_is_finite
  use dkt_kinds, only: wp
  use dkt_registry, only: registry_t, key_t, KEY_REAL, KEY_INTEGER, KEY_LOGICAL, KEY_STRING, &
                          KEY_CHOICE, find_key, has_group, unknown_group_hint, unknown_key_hint, &
                          allowed_text, text_length, lower_case, quoted, itoa
  implicit none
  private
  public :: parse_namelist, apply_override

  integer, parameter :: TOK_WORD = 1, TOK_STRING = 2, TOK_EQ = 3, TOK_COMMA = 4, TOK_END = 5, &
                        TOK_GROUP = 6, TOK_NULL = 7
  type :: token_t
    integer :: kind = 0
    integer :: line = 0
    character(len=:), allocatable :: text !! a word as written, a string without its quotes
  end type token_t

  character(len=*), parameter :: BLANKS = ' '//achar(9)//achar(13)//achar(10)

contains

  !> Apply every item of namelist `text` to the bound configuration. `file` names the text in
  !! messages. On error `err` holds one message naming file, line, group, key and value.
  subroutine parse_namelist(reg, text, file, err)
    type(registry_t), intent(inout) :: reg
    character(len=*), intent(in) :: text, file
    character(len=:), allocatable, intent(out) :: err
    type(token_t), allocatable :: toks(:)
    type(token_t) :: vals(64)
    character(len=:), allocatable :: g, name, first, loc
    integer :: nt, it, nv, gline
    logical :: after_value

    call tokenize(text, file, toks, nt, err)
    if (len(err) > 0) return
    it = 1
    do while (it <= nt)
      loc = at(file, toks(it)%line)
      if (toks(it)%kind /= TOK_GROUP) then
        err = loc//': '''//display(toks(it))//''' is outside a group; a group starts with '// &
              '&name and ends with /'
        return
      end if
      g = toks(it)%text
      gline = toks(it)%line
      it = it + 1
      if (.not. has_group(reg, g)) then
        first = ''
        if (it + 1 <= nt) then
          if (toks(it)%kind == TOK_WORD .and. toks(it + 1)%kind == TOK_EQ) then
            first = ' (first item: '//toks(it)%text//' = '
            if (it + 2 <= nt) first = first//display(toks(it + 2))
            first = first//')'
          end if
        end if
        err = loc//': unknown group &'//g//first//unknown_group_hint(reg, g)
        return
      end if
      do
        if (it > nt) then
          err = at(file, gline)//': group &'//g//' is not closed; end it with /'
          return
        end if
        loc = at(file, toks(it)%line)
        select case (toks(it)%kind)
        case (TOK_END)
          it = it + 1
          exit
        case (TOK_COMMA)
          it = it + 1
        case (TOK_GROUP)
          err = loc//': group &'//g//' is not closed before &'//toks(it)%text// &
                '; end each group with /'
          return
        case (TOK_WORD)
          name = toks(it)%text
          it = it + 1
          if (it <= nt) then ! tolerate a blank before the index: key (2) = v
            if (toks(it)%kind == TOK_WORD .and. toks(it)%text(1:1) == '(') then
              name = name//toks(it)%text
              it = it + 1
            end if
          end if
          if (it > nt) then
            err = loc//': &'//g//' '//name//' has no ''='' and no value'
            return
          else if (toks(it)%kind /= TOK_EQ) then
            err = loc//': &'//g//' expected ''='' after '''//name//''', found '''// &
                  display(toks(it))//''''
            return
          end if
          it = it + 1
          ! Values up to the next 'key =', '/', or '&group'. A comma right after '=' or after
          ! another comma is a null value: that element keeps its value (Fortran namelist rule).
          nv = 0
          after_value = .false.
          do while (it <= nt .and. nv < size(vals))
            if (toks(it)%kind == TOK_COMMA) then
              if (.not. after_value) then
                nv = nv + 1
                vals(nv) = token_t(TOK_NULL, toks(it)%line, '')
              end if
              after_value = .false.
            else if (toks(it)%kind == TOK_STRING .or. &
                     (toks(it)%kind == TOK_WORD .and. .not. starts_item(toks, it, nt))) then
              nv = nv + 1
              vals(nv) = toks(it)
              after_value = .true.
            else
              exit
            end if
            it = it + 1
          end do
          call assign(reg, g, name, vals(1:nv), loc, err)
          if (len(err) > 0) return
        case default
          err = loc//': &'//g//' expected key = value, found '''//display(toks(it))//''''
          return
        end select
      end do
    end do
  end subroutine parse_namelist

  !> Is token `it` the name of a new item (followed by '=', maybe after an index word)?
  pure logical function starts_item(toks, it, nt)
    type(token_t), intent(in) :: toks(:)
    integer, intent(in) :: it, nt
    starts_item = .false.
    if (toks(it)%kind /= TOK_WORD .or. it + 1 > nt) return
    if (toks(it + 1)%kind == TOK_EQ) then
      starts_item = .true.
    else if (it + 2 <= nt) then
      starts_item = toks(it + 1)%kind == TOK_WORD .and. toks(it + 1)%text(1:1) == '(' &
                    .and. toks(it + 2)%kind == TOK_EQ
    end if
  end function starts_item

  !> Apply one override `group.key=value` or `group.key(i)=value` (the --set option). A string
  !! or choice takes the whole text after '=' (quotes optional); other values, and the values
  !! of an array of choices, are split at commas and blanks (each choice's quotes optional).
  !! `file` is the namelist the override follows, for the message.
  subroutine apply_override(reg, spec, file, err)
    type(registry_t), intent(inout) :: reg
    character(len=*), intent(in) :: spec, file
    character(len=:), allocatable, intent(out) :: err
    character(len=:), allocatable :: s, lhs, rhs, g, name, loc
    type(token_t), allocatable :: vals(:)
    integer :: peq, pdot, idx, p, q
    s = trim(adjustl(spec))
    loc = '--set '//s
    if (len(file) > 0) loc = file//': '//loc
    peq = index(s, '=')
    pdot = index(s(:max(peq - 1, 0)), '.')
    if (peq == 0 .or. pdot == 0) then
      err = loc//': expected --set group.key=value, e.g. --set lbm.tau=0.7'
      return
    end if
    lhs = trim(s(:peq - 1))
    rhs = trim(adjustl(s(peq + 1:)))
    g = lower_case(trim(lhs(:pdot - 1)))
    name = lower_case(trim(adjustl(lhs(pdot + 1:))))
    if (.not. has_group(reg, g)) then
      err = loc//': unknown group &'//g//' (key '//name//' = '//rhs//')'// &
            unknown_group_hint(reg, g)
      return
    end if
    p = index(name, '(')
    idx = 0
    if (p > 0) then
      idx = find_key(reg, g, name(:p - 1))
    else
      idx = find_key(reg, g, name)
    end if
    if (idx > 0) then
      if (reg%keys(idx)%kind == KEY_CHOICE .and. reg%keys(idx)%n > 0) then
        call split_words(rhs, vals)
        do q = 1, size(vals)
          vals(q)%kind = TOK_STRING
          vals(q)%text = unquoted(vals(q)%text)
        end do
      else if (reg%keys(idx)%kind == KEY_STRING .or. reg%keys(idx)%kind == KEY_CHOICE) then
        rhs = unquoted(rhs) ! not inside token_t(...): gfortran 12 fails on that (ICE)
        vals = [token_t(TOK_STRING, 0, rhs)]
      else
        call split_words(rhs, vals)
      end if
    else
      call split_words(rhs, vals) ! unknown key: assign() reports it with the value
    end if
    call assign(reg, g, name, vals, loc, err)
  end subroutine apply_override

  !> `text` without the quotes around it, if it is quoted with ' or ".
  function unquoted(text) result(s)
    character(len=*), intent(in) :: text
    character(len=:), allocatable :: s
    integer :: q
    s = text
    q = len(text)
    if (q >= 2) then
      if ((text(1:1) == '''' .or. text(1:1) == '"') .and. text(q:q) == text(1:1)) &
        s = text(2:q - 1)
    end if
  end function unquoted

  subroutine split_words(text, vals)
    character(len=*), intent(in) :: text
    type(token_t), allocatable, intent(out) :: vals(:)
    integer :: p, q
    allocate (vals(0))
    p = 1
    do while (p <= len(text))
      if (index(BLANKS//',', text(p:p)) > 0) then
        p = p + 1
        cycle
      end if
      q = p
      do while (q < len(text))
        if (index(BLANKS//',', text(q + 1:q + 1)) > 0) exit
        q = q + 1
      end do
      vals = [vals, token_t(TOK_WORD, 0, text(p:q))]
      p = q + 1
    end do
  end subroutine split_words

  !> Store `vals` into key `name` (maybe `name(i)`) of group `g`, converting and checking each.
  subroutine assign(reg, g, name, vals, loc, err)
    type(registry_t), intent(inout), target :: reg
    character(len=*), intent(in) :: g, name, loc
    type(token_t), intent(in) :: vals(:)
    character(len=:), allocatable, intent(out) :: err
    type(key_t), pointer :: k
    character(len=:), allocatable :: base, item, elem
    integer :: p, q, idx, first, j, ios, nvals
    real(wp) :: x
    err = ''
    p = index(name, '(')
    base = lower_case(name)
    first = 1
    item = '&'//g//' '//name//' = '//join_values(vals)
    if (p > 0) then
      base = lower_case(name(:p - 1))
      q = index(name, ')')
      ios = 1
      if (q == len(name) .and. q > p + 1) read (name(p + 1:q - 1), *, iostat=ios) first
      if (ios /= 0 .or. verify(trim(adjustl(name(p + 1:max(q - 1, p)))), '0123456789+-') /= 0) then
        err = loc//': '//item//': the index of '''//name//''' is not a whole number'
        return
      end if
    end if
    idx = find_key(reg, g, base)
    if (idx == 0) then
      err = loc//': &'//g//' has no key '''//base//''' (in '//item//')'// &
            unknown_key_hint(reg, g, base)
      return
    end if
    k => reg%keys(idx)
    nvals = count(vals%kind /= TOK_NULL)
    if (nvals == 0) then
      err = loc//': '//item//' has no value; allowed: '//allowed_text(k)//' ('//k%meaning//')'
      return
    end if
    if (p > 0 .and. k%n == 0) then
      err = loc//': '//item//': '//base//' is not an array; write '//base//' = value'
      return
    end if
    if (first < 1 .or. (k%n > 0 .and. first > k%n)) then
      err = loc//': '//item//': index '//itoa(first)//' is out of range; '//base//' has '// &
            itoa(k%n)//' elements, '//base//'(1) to '//base//'('//itoa(k%n)//')'
      return
    end if
    if (first + size(vals) - 1 > max(k%n, 1)) then
      err = loc//': '//item//': too many values; '//base//' takes '//itoa(max(k%n, 1))// &
            trim(merge(' value ', ' values', max(k%n, 1) == 1))
      return
    end if
    do j = 1, size(vals)
      if (vals(j)%kind == TOK_NULL) cycle
      elem = base
      if (k%n > 0) elem = base//'('//itoa(first + j - 1)//')'
      item = '&'//g//' '//elem//' = '//display(vals(j))
      select case (k%kind)
      case (KEY_REAL)
        if (.not. is_real_word(vals(j))) then
          err = loc//': '//item//' is not a real number'
        else
          read (vals(j)%text, *, iostat=ios) x
          if (ios /= 0) then
            err = loc//': '//item//' is not a real number'
          else if (.not. ieee_is_finite(x)) then
            err = loc//': '//item//' is not a finite real number'
          else if (k%n > 0) then
            k%ra(first + j - 1) = x
          else
            k%r = x
          end if
        end if
      case (KEY_INTEGER)
        ios = 1
        if (vals(j)%kind == TOK_WORD .and. verify(vals(j)%text, '+-0123456789') == 0) &
          read (vals(j)%text, *, iostat=ios) k%i
        if (ios /= 0) err = loc//': '//item//' is not an integer'
      case (KEY_LOGICAL)
        select case (lower_case(vals(j)%text))
        case ('.true.', '.t.', 't', 'true')
          k%l = .true.
        case ('.false.', '.f.', 'f', 'false')
          k%l = .false.
        case default
          err = loc//': '//item//' is not a logical'
        end select
        if (vals(j)%kind == TOK_STRING) err = loc//': '//item//' is not a logical'
      case (KEY_STRING, KEY_CHOICE)
        if (len(vals(j)%text) > text_length(k)) then
          err = loc//': '//item//' is too long: '//itoa(len(vals(j)%text))// &
                ' characters, at most '//itoa(text_length(k))
        else if (k%n > 0) then ! an array of choices
          k%sa(first + j - 1)%s = lower_case(vals(j)%text)
        else if (k%kind == KEY_CHOICE) then
          k%s = lower_case(vals(j)%text) ! membership is checked with the ranges (check_key)
        else
          k%s = vals(j)%text
        end if
      end select
      if (len(err) > 0) then
        err = err//'; allowed: '//allowed_text(k)//' ('//k%meaning//')'
        return
      end if
    end do
    k%origin = loc
  end subroutine assign

  !> A real value must look like a number: list-directed input would also take repeat counts
  !! (2*1.0), and a word such as 'T' would then fail with a less clear message.
  pure logical function is_real_word(t)
    type(token_t), intent(in) :: t
    is_real_word = t%kind == TOK_WORD .and. verify(t%text, '+-.0123456789eEdD') == 0 .and. &
                   scan(t%text, '0123456789') > 0
  end function is_real_word

  !> Split `text` into tokens; the only lexical errors are an unclosed string and a bare '&'.
  subroutine tokenize(text, file, toks, nt, err)
    character(len=*), intent(in) :: text, file
    type(token_t), allocatable, intent(out) :: toks(:)
    integer, intent(out) :: nt
    character(len=:), allocatable, intent(out) :: err
    character(len=:), allocatable :: s
    character :: c, quote
    integer :: p, q, line, n
    allocate (toks(64))
    nt = 0
    err = ''
    s = ''
    line = 1
    p = 1
    n = len(text)
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
      else if (c == '''' .or. c == '"') then
        quote = c
        s = ''
        do
          p = p + 1
          if (p > n) then
            err = at(file, line)//': string '//quote//s//' is not closed'
            return
          end if
          if (text(p:p) == achar(10)) then
            err = at(file, line)//': string '//quote//s//' is not closed on its line'
            return
          end if
          if (text(p:p) == quote) then
            if (p < n) then
              if (text(p + 1:p + 1) == quote) then ! a doubled quote stands for one
                s = s//quote
                p = p + 1
                cycle
              end if
            end if
            exit
          end if
          s = s//text(p:p)
        end do
        call push(TOK_STRING, s)
      else
        q = p
        do while (q < n)
          if (scan(text(q + 1:q + 1), BLANKS//',=/!''"') > 0) exit
          q = q + 1
        end do
        if (c == '&') then
          if (q == p) then
            err = at(file, line)//': ''&'' without a group name; a group starts with &name'
            return
          end if
          if (lower_case(text(p + 1:q)) == 'end') then
            call push(TOK_END, text(p:q))
          else
            call push(TOK_GROUP, lower_case(text(p + 1:q)))
          end if
        else
          call push(TOK_WORD, text(p:q))
        end if
        p = q
      end if
      p = p + 1
    end do
  contains
    subroutine push(kind, word)
      integer, intent(in) :: kind
      character(len=*), intent(in) :: word
      type(token_t), allocatable :: tmp(:)
      if (nt == size(toks)) then
        allocate (tmp(2*nt))
        tmp(1:nt) = toks
        call move_alloc(tmp, toks)
      end if
      nt = nt + 1
      toks(nt) = token_t(kind, line, word)
    end subroutine push
  end subroutine tokenize

  ! ---------------------------------------------------------------- small helpers

  function at(file, line) result(s)
    character(len=*), intent(in) :: file
    integer, intent(in) :: line
    character(len=:), allocatable :: s
    s = file//':'//itoa(line)
  end function at

  function display(t) result(s)
    type(token_t), intent(in) :: t
    character(len=:), allocatable :: s
    if (t%kind == TOK_STRING) then
      s = quoted(t%text)
    else
      s = t%text
    end if
  end function display

  function join_values(vals) result(s)
    type(token_t), intent(in) :: vals(:)
    character(len=:), allocatable :: s
    integer :: j
    s = ''
    do j = 1, size(vals)
      if (j > 1) s = s//', '
      s = s//display(vals(j))
    end do
  end function join_values

end module dkt_namelist

!> Namelist input text read into the keys of a registry (module dkt_registry), with messages
!> that name the file, line, group, key and value of whatever is wrong.
!>
!> The intrinsic `read(nml=)` is not used because its errors name neither the key nor the value,
!> and it cannot suggest a spelling or give line numbers. The text accepted is that of the
!> Fortran standard's namelist input (F2008 10.11.3) for the types the registry holds:
!>   - groups `&name ... /`, also closed by `&end` or `$end`, and `$name` for `&name`; several
!>     groups a file, a group given twice is read twice; names in any case;
!>   - items `key = value`, `key(i) = value`, `key(a:b) = v1, v2`, `key(a:b:s) = ...` (bounds
!>     and stride optional, `key(:)`), separated by commas, blanks or newlines;
!>   - a list of values fills an array from its first element (or from element i of `key(i)`,
!>     an extension common to compilers), at most as many values as elements;
!>   - repeat counts `r*value` and `r*'text'`, null values `r*`, an empty item between commas
!>     or right after '=' (a null value leaves its element as it was);
!>   - strings in '..' or ".." with the quote doubled inside, continued over lines;
!>   - logicals: an optional '.', then T or F, then any letters (.true., .f., T, false);
!>   - reals in any list-directed form (1, 1.5, .5, 1e3, 1.5d0, 1.0+3); integers [sign]digits;
!>   - `!` starts a comment outside strings.
!> Extensions kept for convenience: a choice or string may be unquoted, a blank may stand
!> between a key and its index. A key given twice keeps the last value. Values are converted
!> and stored here; ranges and choices are checked later (check_key), after every override.
module dkt_namelist
  use, intrinsic :: ieee_arithmetic, only: ieee_is_finite
  use, intrinsic :: iso_fortran_env, only: int64
  use dkt_kinds, only: wp
  use dkt_registry, only: registry_t, key_t, KEY_REAL, KEY_INTEGER, KEY_LOGICAL, KEY_STRING, &
                          KEY_CHOICE, find_key, has_group, unknown_group_hint, unknown_key_hint, &
                          allowed_text, text_length
  use dkt_text, only: read_real, lower_case, quoted, itoa, append_text
  use dkt_namelist_lexer, only: token_t, tokenize, display, no_blanks, make_token, append, &
                                BLANKS, TOK_WORD, TOK_STRING, TOK_EQ, TOK_COMMA, TOK_END, &
                                TOK_GROUP, TOK_NULL, TOK_SUB, TOK_BAD, BAD_PAREN, BAD_STRING
  implicit none
  private
  public :: parse_namelist, apply_override

  !> One value of an item after its repeat count is split off: `rep` copies of `tok`, or `rep`
  !! null values.
  type :: value_t
    integer :: rep = 1
    logical :: null = .false.
    type(token_t) :: tok
  end type value_t

contains

  !> Apply every item of namelist `text` to the bound configuration. `file` names the text in
  !! messages. On error `err` holds one message naming file, line, group, key and value.
  subroutine parse_namelist(reg, text, file, err)
    type(registry_t), intent(inout) :: reg
    character(len=*), intent(in) :: text, file
    character(len=:), allocatable, intent(out) :: err
    type(token_t), allocatable :: toks(:), vals(:)
    character(len=:), allocatable :: g, name, first, loc
    integer :: nt, it, nv, gline
    logical :: after_value

    err = ''
    call tokenize(text, toks, nt)
    allocate (vals(16))
    it = 1
    do while (it <= nt)
      loc = at(file, toks(it)%line)
      if (toks(it)%kind == TOK_BAD) then
        err = loc//': '//bad_text(toks(it), '')
        return
      else if (toks(it)%kind /= TOK_GROUP) then
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
          if (it <= nt) then ! the index or section, maybe after a blank: key (2) = v
            if (toks(it)%kind == TOK_SUB) then
              name = name//toks(it)%text
              it = it + 1
            end if
          end if
          if (it > nt) then
            err = loc//': &'//g//' '//name//' has no ''='' and no value'
            return
          else if (toks(it)%kind == TOK_BAD) then ! key(1 = 1.0: the index is not closed
            err = loc//': &'//g//' '//name//': '//bad_text(toks(it), name)
            return
          else if (toks(it)%kind /= TOK_EQ) then
            err = loc//': &'//g//' expected ''='' after '''//name//''', found '''// &
                  display(toks(it))//''''
            return
          end if
          it = it + 1
          ! Values up to the next 'key =', '/', or '&group'. A comma right after '=' or after
          ! another comma is a null value: that element keeps its value (Fortran namelist
          ! rule). A comma before '/' or before the next key ends the list and is no null.
          nv = 0
          after_value = .false.
          do while (it <= nt)
            if (toks(it)%kind == TOK_COMMA) then
              if (.not. after_value) call add_value(make_token(TOK_NULL, toks(it)%line, ''))
              after_value = .false.
            else if (toks(it)%kind == TOK_STRING .or. toks(it)%kind == TOK_SUB .or. &
                     (toks(it)%kind == TOK_WORD .and. .not. starts_item(toks, it, nt))) then
              call add_value(toks(it))
              after_value = .true.
            else
              exit
            end if
            it = it + 1
          end do
          if (it <= nt) then ! key = 'text: the string is not closed
            if (toks(it)%kind == TOK_BAD) then ! at the line of the quote or '(' not closed
              err = at(file, toks(it)%line)//': &'//g//' '//name//' = '//join_values(vals(1:nv))
              if (nv > 0) err = err//', '
              err = err//toks(it)%text//': '//bad_text(toks(it), '')
              ! unless the tokenizer already named a string that ran over lines
              if (index(toks(it)%why, 'several lines') == 0) err = err//quote_hint(vals(1:nv))
              return
            end if
          end if
          call assign(reg, g, name, vals(1:nv), loc, err)
          if (len(err) > 0) return
        case (TOK_BAD)
          err = loc//': &'//g//': '//bad_text(toks(it), '')
          return
        case default
          err = loc//': &'//g//' expected key = value, found '''//display(toks(it))//''''
          return
        end select
      end do
    end do
  contains
    subroutine add_value(t)
      type(token_t), intent(in) :: t
      call append(vals, nv, t)
    end subroutine add_value
  end subroutine parse_namelist

  !> Append `t` to the first `n` tokens of `list`, growing it as needed.

  !> Is token `it` the name of a new item (followed by '=', maybe after an index)?
  pure logical function starts_item(toks, it, nt)
    type(token_t), intent(in) :: toks(:)
    integer, intent(in) :: it, nt
    starts_item = .false.
    if (toks(it)%kind /= TOK_WORD .or. it + 1 > nt) return
    if (toks(it + 1)%kind == TOK_EQ) then
      starts_item = .true.
    else if (toks(it + 1)%kind == TOK_BAD) then ! key(1 = ..: an index not closed
      starts_item = toks(it + 1)%bad == BAD_PAREN
    else if (it + 2 <= nt) then
      starts_item = toks(it + 1)%kind == TOK_SUB .and. toks(it + 2)%kind == TOK_EQ
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
    integer :: peq, pdot, idx, p, q, star
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
    name = lower_case(no_blanks(lhs(pdot + 1:)))
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
          ! r*'text' or r*text: the count is kept apart from the choice; r* (nulls) stays a word
          star = index(vals(q)%text, '*')
          if (star == len(vals(q)%text)) cycle
          vals(q)%kind = TOK_STRING
          if (star > 1 .and. scan(vals(q)%text(:max(star - 1, 1)), '''"') == 0) then
            vals(q)%rep = vals(q)%text(:star - 1)
            vals(q)%text = vals(q)%text(star + 1:)
          end if
          vals(q)%text = unquoted(vals(q)%text)
        end do
      else if (reg%keys(idx)%kind == KEY_STRING .or. reg%keys(idx)%kind == KEY_CHOICE) then
        rhs = unquoted(rhs)
        vals = [make_token(TOK_STRING, 0, rhs)]
      else
        call split_words(rhs, vals)
      end if
      ! On the command line an empty value is a slip, not the null value of a file.
      if (size(vals) == 0) then
        err = loc//': &'//g//' '//name//' = has no value; allowed: '// &
              allowed_text(reg%keys(idx))//' ('//reg%keys(idx)%meaning//')'
        return
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
      vals = [vals, make_token(TOK_WORD, 0, text(p:q))]
      p = q + 1
    end do
  end subroutine split_words

  !> Store `raw` (value tokens, nulls included) into key `name` of group `g`; `name` may carry
  !! an index or a section, `name(i)`, `name(a:b)`, `name(a:b:s)`. Repeat counts are expanded
  !! here; each value is converted and checked for its type. An array that grows (key_t%grows,
  !! with the registry's resize hook set) is read as if it had reg%limit elements and is
  !! resized when a value goes beyond its size, to twice its size at least, so that n elements
  !! cost O(n) copies; the registry notes what its final size must hold (top, reach).
  subroutine assign(reg, g, name, raw, loc, err)
    type(registry_t), intent(inout), target :: reg
    character(len=*), intent(in) :: g, name, loc
    type(token_t), intent(in) :: raw(:)
    character(len=:), allocatable, intent(out) :: err
    type(key_t), pointer :: k
    type(value_t), allocatable :: vals(:)
    character(len=:), allocatable :: base, item, why, takes
    integer :: p, idx, first, step, slots, j, r, e, filled, n
    integer(int64) :: total
    logical :: stored, growing, open_end
    err = ''
    p = index(name, '(')
    base = lower_case(name)
    if (p > 0) base = lower_case(name(:p - 1))
    item = '&'//g//' '//name//' = '//join_values(raw)
    idx = find_key(reg, g, base)
    if (idx == 0) then
      err = loc//': &'//g//' has no key '''//base//''' (in '//item//')'// &
            unknown_key_hint(reg, g, base)
      return
    end if
    k => reg%keys(idx)
    call split_repeats(raw, vals, why)
    if (len(why) > 0) then
      err = loc//': '//item//': '//why
      return
    end if

    ! The elements the values go to: first, first + step, ... (slots of them).
    growing = k%grows .and. associated(reg%resize)
    n = k%n
    if (growing) n = reg%limit
    open_end = .true.
    if (p > 0) then
      if (k%n == 0) then
        err = loc//': '//item//': '//base//' is not an array; write '//base//' = value'
        return
      end if
      if (name(len(name):) /= ')' .or. index(name(p + 1:), '(') > 0) then
        ! x(1)%re, x(1)(2), x(1: a component or a second index is not an element of an array
        err = loc//': '//item//': '''//name//''' is not an element of '//base//': write '// &
              base//'(i), '//base//'(a:b) or '//base//'(a:b:s): one index in one pair of '// &
              'parentheses, nothing after them'
        return
      end if
      call select_elements(name(p + 1:len(name) - 1), base, n, first, step, slots, open_end, &
                           why)
      if (len(why) > 0) then
        err = loc//': '//item//': '//why//k%size_note
        return
      end if
      if (index(name, ':') == 0) then
        takes = 'from '//name//' on, '//base//' takes '//itoa(slots)
      else
        takes = 'the section '//name//' takes '//itoa(slots)
      end if
    else
      first = 1
      step = 1
      slots = max(n, 1)
      takes = base//' takes '//itoa(slots)
    end if
    total = 0
    do j = 1, size(vals)
      total = total + vals(j)%rep
    end do
    if (total > slots) then
      err = loc//': '//item//': too many values ('//itoa64(total)
      if (total > size(vals)) err = err//', counting repeats'
      err = err//'); '//takes//trim(merge(' value ', ' values', slots == 1))//k%size_note
      return
    end if
    if (growing) then
      ! Read with the final size n in place of limit, the item must select the same elements
      ! and take its values: reach is the least n for which it does. A selection that runs to
      ! the end of the array (key = .., key(i) = .., key(a::s) = ..) needs room for every value,
      ! nulls too; a section with an upper bound, for every element it selects. (Of a section
      ! a::s with s < 0, only a = limit with at most one value gets here.)
      if (open_end) then
        reg%reach = max(reg%reach, first + (max(int(total), 1) - 1)*step)
      else
        reg%reach = max(reg%reach, first, first + (slots - 1)*step)
      end if
    end if

    filled = 0
    stored = .false.
    do j = 1, size(vals)
      do r = 1, vals(j)%rep
        e = first + filled*step
        filled = filled + 1
        if (vals(j)%null) cycle
        if (k%n == 0) e = 0
        if (growing) then
          reg%top = max(reg%top, e)
          if (e > k%n) call reg%resize(reg%owner, reg%keys, min(reg%limit, max(e, 2*k%n)))
        end if
        call store(k, e, vals(j)%tok, '&'//g//' '//element(base, e)//' = '// &
                   display(vals(j)%tok), why)
        if (len(why) > 0) then
          ! A value that does not convert, of an array that grows: counted, and the read goes
          ! on, so that top is that of the whole input; the owner reads again with the arrays
          ! at their final size for the message (config_load).
          if (growing) then
            reg%skipped = reg%skipped + 1
            cycle
          end if
          err = loc//': '//why//'; allowed: '//allowed_text(k)//' ('//k%meaning//')'
          return
        end if
        stored = .true.
      end do
    end do
    if (stored) k%origin = loc
  end subroutine assign

  !> `base` for a scalar (e = 0), `base(e)` for element e of an array.
  function element(base, e) result(s)
    character(len=*), intent(in) :: base
    integer, intent(in) :: e
    character(len=:), allocatable :: s
    s = base
    if (e > 0) s = base//'('//itoa(e)//')'
  end function element

  !> Split the repeat count off each value: r*c is r copies of c, r* is r null values; a null
  !! token is one null value. `why` says what is wrong with a repeat count ('' if nothing).
  subroutine split_repeats(raw, vals, why)
    type(token_t), intent(in) :: raw(:)
    type(value_t), allocatable, intent(out) :: vals(:)
    character(len=:), allocatable, intent(out) :: why
    character(len=:), allocatable :: count_text
    integer :: j, star
    allocate (vals(size(raw)))
    why = ''
    do j = 1, size(raw)
      vals(j)%tok = raw(j)
      vals(j)%null = raw(j)%kind == TOK_NULL
      count_text = ''
      if (raw(j)%kind == TOK_STRING .and. allocated(raw(j)%rep)) then
        count_text = raw(j)%rep
        vals(j)%tok%rep = ''
      else if (raw(j)%kind == TOK_WORD) then
        star = index(raw(j)%text, '*')
        ! A word with '*' is a repeat if what precedes the '*' looks like a number at all;
        ! anything else (x*2) is left to the type check of the value.
        if (star > 1) then
          if (verify(raw(j)%text(:star - 1), '+-.0123456789eEdD') == 0 .and. &
              scan(raw(j)%text(:star - 1), '0123456789') > 0) then
            count_text = raw(j)%text(:star - 1)
            vals(j)%tok%text = raw(j)%text(star + 1:)
            vals(j)%null = len(vals(j)%tok%text) == 0
          end if
        end if
      end if
      if (len(count_text) == 0) cycle
      if (.not. whole_number(count_text, vals(j)%rep)) then
        why = 'the repeat count '''//count_text//''' of '''//display(raw(j))//''' is not '// &
              'a whole number of integer size; write r*value with r = 1, 2, ...'
        return
      else if (vals(j)%rep < 1) then
        why = 'the repeat count '//count_text//' of '''//display(raw(j))//''' is not '// &
              'positive; write r*value with r = 1, 2, ...'
        return
      end if
    end do
  end subroutine split_repeats

  !> The elements an index `sub` ('i', 'a:b' or 'a:b:s', bounds and stride optional) selects
  !! of an array `base` of n elements: first, first + step, ... (count of them). An index i
  !! selects elements i..n (a list of values after key(i) fills on from i). `open_end`: the
  !! selection runs to the end of the array (an index, or a section without an upper bound),
  !! so that its count follows n. `why` says what is wrong ('' if nothing).
  subroutine select_elements(sub, base, n, first, step, count, open_end, why)
    character(len=*), intent(in) :: sub, base
    integer, intent(in) :: n
    integer, intent(out) :: first, step, count
    logical, intent(out) :: open_end
    character(len=:), allocatable, intent(out) :: why
    character(len=:), allocatable :: des, range_text
    character(len=len(sub)) :: part(3) !! lower bound, upper bound, stride as written
    character(len=11), parameter :: WHAT(3) = ['lower bound', 'upper bound', 'stride     ']
    integer :: c1, c2, v(3), j, last
    des = base//'('//sub//')'
    range_text = base//' has '//itoa(n)//trim(merge(' element ', ' elements', n == 1))//', '// &
                 base//'(1) to '//base//'('//itoa(n)//')'
    why = ''
    first = 1
    step = 1
    count = 0
    open_end = .true.
    if (scan(sub, ',') > 0) then
      why = base//' has one dimension: write '//base//'(i), '//base//'(a:b) or '//base//'(a:b:s)'
      return
    end if
    c1 = index(sub, ':')
    if (c1 == 0) then
      if (too_large(sub)) then
        why = 'index '//sub//' is out of range; '//range_text
      else if (.not. whole_number(sub, first)) then
        why = 'the index of '''//des//''' is not a whole number'
      else if (first < 1 .or. first > n) then
        why = 'index '//itoa(first)//' is out of range; '//range_text
      else
        count = n - first + 1
      end if
      return
    end if
    c2 = index(sub(c1 + 1:), ':')
    if (c2 > 0) c2 = c1 + c2
    if (c2 > 0) then
      if (index(sub(c2 + 1:), ':') > 0) then
        why = ''''//des//''' is not an index: write '//base//'(i), '//base//'(a:b) or '// &
              base//'(a:b:s)'
        return
      end if
      part = [character(len=len(sub)) :: sub(:c1 - 1), sub(c1 + 1:c2 - 1), sub(c2 + 1:)]
    else
      part = [character(len=len(sub)) :: sub(:c1 - 1), sub(c1 + 1:), '']
    end if
    open_end = len_trim(part(2)) == 0
    v = [1, n, 1] ! the defaults of an omitted bound or stride
    do j = 1, 3
      if (len_trim(part(j)) == 0) cycle
      if (too_large(trim(part(j)))) then
        why = 'the '//trim(WHAT(j))//' '//trim(part(j))//' of '''//des// &
              ''' is out of range; '//range_text
        return
      else if (.not. whole_number(trim(part(j)), v(j))) then
        why = 'the '//trim(WHAT(j))//' '''//trim(part(j))//''' of '''//des// &
              ''' is not a whole number'
        return
      end if
    end do
    if (v(3) == 0) then
      why = 'the stride of '''//des//''' is 0; a section a:b:s needs a stride s other than 0'
      return
    end if
    first = v(1)
    step = v(3)
    count = max(0, (v(2) - v(1) + v(3))/v(3))
    if (count == 0) then
      why = 'the section '''//des//''' selects no element (from '//itoa(v(1))//' to '// &
            itoa(v(2))//' in steps of '//itoa(v(3))//')'
      return
    end if
    ! The bounds themselves may lie outside (x(1:7:2) of 6 elements); the elements may not.
    last = first + (count - 1)*step
    do j = 1, 2
      e_check: block
        integer :: e
        e = merge(first, last, j == 1)
        if (e < 1 .or. e > n) then
          why = 'the section '''//des//''' selects element '//itoa(e)// &
                ', out of range; '//range_text
          return
        end if
      end block e_check
    end do
  end subroutine select_elements

  !> Convert value `t` for key `k` and store it into element e (0: the scalar). `item` names
  !! it in the message `why` ('' when stored).
  subroutine store(k, e, t, item, why)
    type(key_t), intent(inout) :: k
    integer, intent(in) :: e
    type(token_t), intent(in) :: t
    character(len=*), intent(in) :: item
    character(len=:), allocatable, intent(out) :: why
    character(len=:), allocatable :: w
    real(wp) :: x
    integer :: i, ios
    why = ''
    select case (k%kind)
    case (KEY_REAL)
      select case (real_form(t))
      case (1)
        call read_real(t%text, x, ios)
        if (ios /= 0) then
          why = item//' is not a real number'
        else if (.not. ieee_is_finite(x)) then
          why = item//' is not a finite real number (too large)'
        else if (e > 0) then
          k%ra(e) = x
        else
          k%r = x
        end if
      case (2)
        why = item//' is not a finite real number'
      case default
        why = item//' is not a real number'
      end select
    case (KEY_INTEGER)
      if (t%kind /= TOK_WORD .or. .not. whole_number(t%text, i)) then
        why = item//' is not an integer'
        if (t%kind == TOK_WORD .and. verify(t%text, '+-0123456789') == 0 .and. &
            scan(t%text, '0123456789') > 0) why = item//' is too large for an integer (at '// &
                                              'most '//itoa(huge(i))//' in size)'
      else
        k%i = i
      end if
    case (KEY_LOGICAL)
      ! Fortran's logical input: an optional '.', then T or F, then anything (.true., tru).
      w = lower_case(t%text)
      if (len(w) > 0) then
        if (w(1:1) == '.') w = w(2:)
      end if
      if (t%kind /= TOK_WORD .or. len(w) == 0) then
        why = item//' is not a logical'
      else if (w(1:1) == 't') then
        k%l = .true.
      else if (w(1:1) == 'f') then
        k%l = .false.
      else
        why = item//' is not a logical'
      end if
    case (KEY_STRING, KEY_CHOICE)
      if (len(t%text) > text_length(k)) then
        why = item//' is too long: '//itoa(len(t%text))//' characters, at most '// &
              itoa(text_length(k))
      else if (e > 0) then ! an array of choices
        k%sa(e)%s = lower_case(t%text)
      else if (k%kind == KEY_CHOICE) then
        k%s = lower_case(t%text) ! membership is checked with the ranges (check_key)
      else
        k%s = t%text
      end if
    end select
  end subroutine store

  !> 1 if `t` is a real number as list-directed input writes it ([sign] digits with an optional
  !! point, then an optional exponent E/D[sign]digits or sign digits), 2 for Inf or NaN, 0
  !! otherwise. The form is checked before the conversion because list-directed input would
  !! also take a repeat count or stop at a blank or a slash.
  integer function real_form(t) result(f)
    type(token_t), intent(in) :: t
    character(len=:), allocatable :: s
    integer :: p, nd
    f = 0
    if (t%kind /= TOK_WORD) return
    s = lower_case(t%text)
    p = 1
    if (len(s) == 0) return
    if (s(1:1) == '+' .or. s(1:1) == '-') p = 2
    if (s(p:) == 'inf' .or. s(p:) == 'infinity' .or. s(p:) == 'nan' .or. &
        (index(s(p:), 'nan(') == 1 .and. s(len(s):) == ')')) then
      f = 2
      return
    end if
    nd = 0
    call digits_at(nd)
    if (p <= len(s)) then
      if (s(p:p) == '.') then
        p = p + 1
        call digits_at(nd)
      end if
    end if
    if (nd == 0) return
    if (p > len(s)) then
      f = 1
      return
    end if
    if (s(p:p) == 'e' .or. s(p:p) == 'd') then
      p = p + 1
      if (p <= len(s)) then
        if (s(p:p) == '+' .or. s(p:p) == '-') p = p + 1
      end if
    else if (s(p:p) == '+' .or. s(p:p) == '-') then
      p = p + 1
    else
      return
    end if
    nd = 0
    call digits_at(nd)
    if (nd > 0 .and. p > len(s)) f = 1
  contains
    subroutine digits_at(n)
      integer, intent(inout) :: n
      do while (p <= len(s))
        if (index('0123456789', s(p:p)) == 0) exit
        p = p + 1
        n = n + 1
      end do
    end subroutine digits_at
  end function real_form

  !> Is `text` written as a whole number, [sign]digits (of any size)?
  pure logical function digits_form(text)
    character(len=*), intent(in) :: text
    integer :: p
    digits_form = .false.
    p = 1
    if (len(text) == 0) return
    if (text(1:1) == '+' .or. text(1:1) == '-') p = 2
    if (p > len(text)) return
    digits_form = verify(text(p:), '0123456789') == 0
  end function digits_form

  !> Is `text` a whole number too large for an integer? An index so written is out of range
  !! rather than 'not a whole number'.
  logical function too_large(text)
    character(len=*), intent(in) :: text
    integer :: i
    too_large = digits_form(text) .and. .not. whole_number(text, i)
  end function too_large

  !> Is `text` a whole number ([sign]digits) that fits an integer? Then `i` is its value.
  logical function whole_number(text, i)
    character(len=*), intent(in) :: text
    integer, intent(out) :: i
    integer :: ios
    i = 0
    whole_number = .false.
    if (.not. digits_form(text)) return
    read (text, *, iostat=ios) i
    whole_number = ios == 0
  end function whole_number

  !> For a string not closed after values `vals` of its item: a string among them that holds
  !! an '=' most likely swallowed the next items (sides = 'wall, lower = 'periodic'), so its
  !! own closing quote is the one missing. '' if there is none.
  function quote_hint(vals) result(s)
    type(token_t), intent(in) :: vals(:)
    character(len=:), allocatable :: s
    integer :: j, q
    s = ''
    do j = 1, size(vals)
      if (vals(j)%kind /= TOK_STRING) cycle
      if (index(vals(j)%text, '=') == 0) cycle
      q = scan(vals(j)%text//',', ', ')
      s = '; the string '//display(vals(j))//' holds an ''='': is the closing quote after '// &
          quoted(vals(j)%text(:q - 1))//' missing?'
      return
    end do
  end function quote_hint

  !> What is wrong at a TOK_BAD token `t`; `key` is the key name written right before an
  !! unclosed index ('' elsewhere).
  function bad_text(t, key) result(s)
    type(token_t), intent(in) :: t
    character(len=*), intent(in) :: key
    character(len=:), allocatable :: s, k
    select case (t%bad)
    case (BAD_PAREN)
      k = key
      if (len(k) == 0) k = 'key'
      s = ''''//key//t%text//''' has no closing '')''; an index is written '//k//'(i), '// &
          k//'(a:b) or '//k//'(a:b:s)'
    case (BAD_STRING)
      s = 'the string '//t%text//' is not closed; '//t%why
    case default
      s = ''''//t%text//''' without a group name; a group starts with &name'
    end select
  end function bad_text

  ! ---------------------------------------------------------------- small helpers

  function at(file, line) result(s)
    character(len=*), intent(in) :: file
    integer, intent(in) :: line
    character(len=:), allocatable :: s
    s = file//':'//itoa(line)
  end function at

  !> The values as a message shows them: the first SHOWN of a longer list, then how many there
  !! are (a refused list of 10^5 values is not echoed whole).
  function join_values(vals) result(s)
    type(token_t), intent(in) :: vals(:)
    character(len=:), allocatable :: s
    integer, parameter :: SHOWN = 10
    integer :: j, n
    n = 0
    call append_text(s, n, '')
    do j = 1, min(size(vals), SHOWN)
      if (j > 1) call append_text(s, n, ', ')
      call append_text(s, n, display(vals(j)))
    end do
    if (size(vals) > SHOWN) call append_text(s, n, ', ... ('//itoa(size(vals))//' values)')
    s = s(:n)
  end function join_values

  function itoa64(i) result(s)
    integer(int64), intent(in) :: i
    character(len=:), allocatable :: s
    character(len=24) :: buf
    write (buf, '(i0)') i
    s = trim(buf)
  end function itoa64

end module dkt_namelist

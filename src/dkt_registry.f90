!> The input keys of a configuration: for each key its group, name, type, unit, range or
!> choices and meaning, bound by pointer to the component of the configuration that holds its
!> value. Parsing (dkt_namelist), range checks, --print-defaults and the documentation are all
!> derived from it, so a key is declared once (in dkt_config).
!>
!> The registry also gives the text form of values (reals round-trip exactly) and of what a key
!> accepts, and the hints for an unknown group or key (the known names and the closest one).
module dkt_registry
  use dkt_kinds, only: wp
  use dkt_text, only: fmt_real, itoa, lower_case, quoted, append_text
  implicit none
  private
  public :: key_t, registry_t
  public :: KEY_REAL, KEY_INTEGER, KEY_LOGICAL, KEY_STRING, KEY_CHOICE
  public :: add_real, add_reals, add_integer, add_logical, add_string, add_choice, add_choices
  public :: find_key, has_group, origin_of, blame, unknown_group_hint, unknown_key_hint, check_key
  public :: value_text, allowed_text, type_name, text_length, rebind_grown, final_size

  integer, parameter :: KEY_REAL = 1, KEY_INTEGER = 2, KEY_LOGICAL = 3, KEY_STRING = 4, &
                        KEY_CHOICE = 5

  !> One text value of an array of choices. Each element gets its own pointer because
  !! gfortran 12 loses the length of a deferred-length character array pointer (len = 0).
  type :: text_ref_t
    character(len=:), pointer :: s => null()
  end type text_ref_t

  !> One input key: where its value lives, what it accepts and what it means.
  type :: key_t
    character(len=:), allocatable :: group   !! group name, lower case
    character(len=:), allocatable :: name    !! key name, lower case
    integer :: kind = 0                      !! KEY_REAL .. KEY_CHOICE
    integer :: n = 0                         !! number of elements of an array key; 0 = scalar
                                             !! (arrays: KEY_REAL and KEY_CHOICE)
    character(len=:), allocatable :: unit    !! physical unit; '-' for a pure number
    character(len=:), allocatable :: meaning !! one line, no '|' (it goes into markdown tables)
    character(len=:), allocatable :: choices !! allowed values of a choice, blank-separated
    logical :: has_lo = .false., lo_open = .false., has_hi = .false., hi_open = .false.
    logical :: zero_ok = .false.             !! 0 is allowed besides the range ("use the rule")
    logical :: auto_ok = .false.             !! -1 is allowed besides the range ("automatic")
    real(wp) :: lo = 0.0_wp, hi = 0.0_wp     !! range bounds (integers are compared as reals)
    character(len=:), allocatable :: origin  !! 'file:line' or '--set ...' of the last assignment
    !> an array sized from the input: what its size follows, appended to an index error
    character(len=:), allocatable :: size_note
    !> an array sized from the input: it grows while a registry with a resize hook reads
    logical :: grows = .false.
    real(wp), pointer :: r => null()
    real(wp), pointer :: ra(:) => null()
    integer, pointer :: i => null()
    logical, pointer :: l => null()
    character(len=:), pointer :: s => null()
    type(text_ref_t), allocatable :: sa(:)   !! the elements of an array of choices
  end type key_t

  abstract interface
    !> Give the arrays of the keys that grow (key_t%grows), owned by `owner`, n elements each,
    !! keeping the values of the elements they had, and bind those keys to the new arrays.
    subroutine resize_hook(owner, keys, n)
      import :: key_t
      class(*), pointer, intent(in) :: owner
      type(key_t), intent(inout) :: keys(:)
      integer, intent(in) :: n
    end subroutine resize_hook
  end interface

  !> The keys of a configuration, in the order they are documented and printed.
  !!
  !! A registry with a `resize` hook reads the arrays of the keys that grow without knowing
  !! their size in advance: an element beyond an array's size makes the parser call the hook
  !! (up to `limit` elements), so the text is read once and the owner sizes the arrays after
  !! reading (final_size). Such a read also notes what that final size must hold (`top`,
  !! `reach`) and goes on past a value of such an array that does not convert (`skipped`).
  type :: registry_t
    type(key_t), allocatable :: keys(:)
    character(len=:), allocatable :: groups  !! group names in order, blank-separated
    procedure(resize_hook), pointer, nopass :: resize => null() !! null: every size is fixed
    class(*), pointer :: owner => null()     !! what `resize` resizes (the configuration)
    integer :: limit = 0   !! the most elements an array that grows may get
    integer :: top = 0     !! the highest element a value went to in an array that grows
    !> the fewest elements the arrays that grow need for every item read to select, at that
    !! size, the elements it selected (select_elements, the count of values)
    integer :: reach = 0
    !> values for arrays that grow that did not convert; the read went on past them, counting
    !! elements, so that its top is that of the whole input
    integer :: skipped = 0
  end type registry_t

contains

  ! ---------------------------------------------------------------- construction

  subroutine add_key(reg, group, name, kind, unit, meaning)
    type(registry_t), intent(inout) :: reg
    character(len=*), intent(in) :: group, name, unit, meaning
    integer, intent(in) :: kind
    type(key_t) :: k
    if (.not. allocated(reg%keys)) allocate (reg%keys(0))
    if (.not. allocated(reg%groups)) reg%groups = ''
    k%group = lower_case(group)
    k%name = lower_case(name)
    k%kind = kind
    k%unit = unit
    k%meaning = meaning
    k%choices = ''
    k%origin = ''
    k%size_note = ''
    reg%keys = [reg%keys, k]
    if (word_index(reg%groups, k%group) == 0) reg%groups = trim(adjustl(reg%groups//' '//k%group))
  end subroutine add_key

  !> Register a real key bound to `x`; the range is given by any of gt, ge, lt, le.
  subroutine add_real(reg, group, name, x, unit, meaning, gt, ge, lt, le, zero_ok, auto_ok)
    type(registry_t), intent(inout) :: reg
    character(len=*), intent(in) :: group, name, unit, meaning
    real(wp), intent(inout), target :: x
    real(wp), intent(in), optional :: gt, ge, lt, le
    logical, intent(in), optional :: zero_ok, auto_ok
    call add_key(reg, group, name, KEY_REAL, unit, meaning)
    reg%keys(size(reg%keys))%r => x
    call set_range(reg%keys(size(reg%keys)), gt, ge, lt, le, zero_ok)
    if (present(auto_ok)) reg%keys(size(reg%keys))%auto_ok = auto_ok
  end subroutine add_real

  !> Register a real array key bound to `x` (documented as name(size(x))).
  subroutine add_reals(reg, group, name, x, unit, meaning, gt, ge, lt, le)
    type(registry_t), intent(inout) :: reg
    character(len=*), intent(in) :: group, name, unit, meaning
    real(wp), intent(inout), target, contiguous :: x(:)
    real(wp), intent(in), optional :: gt, ge, lt, le
    call add_key(reg, group, name, KEY_REAL, unit, meaning)
    reg%keys(size(reg%keys))%ra => x
    reg%keys(size(reg%keys))%n = size(x)
    call set_range(reg%keys(size(reg%keys)), gt, ge, lt, le)
  end subroutine add_reals

  !> Register an integer key bound to `x`, with an optional range ge..le.
  subroutine add_integer(reg, group, name, x, unit, meaning, ge, le)
    type(registry_t), intent(inout) :: reg
    character(len=*), intent(in) :: group, name, unit, meaning
    integer, intent(inout), target :: x
    integer, intent(in), optional :: ge, le
    call add_key(reg, group, name, KEY_INTEGER, unit, meaning)
    reg%keys(size(reg%keys))%i => x
    if (present(ge)) call set_range(reg%keys(size(reg%keys)), ge=real(ge, wp))
    if (present(le)) call set_range(reg%keys(size(reg%keys)), le=real(le, wp))
  end subroutine add_integer

  subroutine add_logical(reg, group, name, x, meaning)
    type(registry_t), intent(inout) :: reg
    character(len=*), intent(in) :: group, name, meaning
    logical, intent(inout), target :: x
    call add_key(reg, group, name, KEY_LOGICAL, '-', meaning)
    reg%keys(size(reg%keys))%l => x
  end subroutine add_logical

  !> Register a free-text key bound to `x`; the value may not be longer than len(x).
  subroutine add_string(reg, group, name, x, meaning)
    type(registry_t), intent(inout) :: reg
    character(len=*), intent(in) :: group, name, meaning
    character(len=*), intent(inout), target :: x
    call add_key(reg, group, name, KEY_STRING, '-', meaning)
    reg%keys(size(reg%keys))%s => x
  end subroutine add_string

  !> Register a key whose value is one of `choices` (blank-separated, lower case).
  subroutine add_choice(reg, group, name, x, choices, meaning)
    type(registry_t), intent(inout) :: reg
    character(len=*), intent(in) :: group, name, choices, meaning
    character(len=*), intent(inout), target :: x
    call add_key(reg, group, name, KEY_CHOICE, '-', meaning)
    reg%keys(size(reg%keys))%s => x
    reg%keys(size(reg%keys))%choices = trim(adjustl(choices))
  end subroutine add_choice

  !> Register an array key bound to `x` whose every element is one of `choices`
  !! (documented as name(size(x))).
  subroutine add_choices(reg, group, name, x, choices, meaning)
    type(registry_t), intent(inout) :: reg
    character(len=*), intent(in) :: group, name, choices, meaning
    character(len=*), intent(inout), target :: x(:)
    integer :: j
    call add_key(reg, group, name, KEY_CHOICE, '-', meaning)
    associate (k => reg%keys(size(reg%keys)))
      allocate (k%sa(size(x)))
      do j = 1, size(x)
        k%sa(j)%s => x(j)
      end do
      k%n = size(x)
      k%choices = trim(adjustl(choices))
    end associate
  end subroutine add_choices

  !> Bind each key of `keys` that grows to the value of the key of the same group and name in
  !! `fresh`, a registration of the arrays just resized (for a resize hook: the keys are
  !! declared once, by the procedure that registers them).
  subroutine rebind_grown(keys, fresh)
    type(key_t), intent(inout) :: keys(:)
    type(registry_t), intent(inout) :: fresh
    integer :: j, i
    do j = 1, size(keys)
      if (.not. keys(j)%grows) cycle
      i = find_key(fresh, keys(j)%group, keys(j)%name)
      keys(j)%n = fresh%keys(i)%n
      keys(j)%ra => fresh%keys(i)%ra
      if (allocated(fresh%keys(i)%sa)) call move_alloc(fresh%keys(i)%sa, keys(j)%sa)
    end do
  end subroutine rebind_grown

  !> After a read into arrays that grow: give them their final size, n elements, and end the
  !! growing, so that later reads see fixed sizes.
  subroutine final_size(reg, n)
    type(registry_t), intent(inout) :: reg
    integer, intent(in) :: n
    call reg%resize(reg%owner, reg%keys, n)
    reg%resize => null()
  end subroutine final_size

  subroutine set_range(k, gt, ge, lt, le, zero_ok)
    type(key_t), intent(inout) :: k
    real(wp), intent(in), optional :: gt, ge, lt, le
    logical, intent(in), optional :: zero_ok
    if (present(gt)) then
      k%has_lo = .true.; k%lo_open = .true.; k%lo = gt
    end if
    if (present(ge)) then
      k%has_lo = .true.; k%lo_open = .false.; k%lo = ge
    end if
    if (present(lt)) then
      k%has_hi = .true.; k%hi_open = .true.; k%hi = lt
    end if
    if (present(le)) then
      k%has_hi = .true.; k%hi_open = .false.; k%hi = le
    end if
    if (present(zero_ok)) k%zero_ok = zero_ok
  end subroutine set_range

  ! ---------------------------------------------------------------- look-up

  !> Index of key `name` of `group` in the registry, 0 if there is none.
  pure integer function find_key(reg, group, name) result(idx)
    type(registry_t), intent(in) :: reg
    character(len=*), intent(in) :: group, name
    do idx = 1, size(reg%keys)
      if (reg%keys(idx)%group == lower_case(group) .and. reg%keys(idx)%name == lower_case(name)) &
        return
    end do
    idx = 0
  end function find_key

  !> Is `group` a group of the registry?
  logical function has_group(reg, group)
    type(registry_t), intent(in) :: reg
    character(len=*), intent(in) :: group
    has_group = word_index(reg%groups, lower_case(group)) > 0
  end function has_group

  !> Where the key was last set ('file:line' or the --set option), or `fallback` if never.
  function origin_of(reg, group, name, fallback) result(src)
    type(registry_t), intent(in) :: reg
    character(len=*), intent(in) :: group, name, fallback
    character(len=:), allocatable :: src
    integer :: idx
    src = fallback
    idx = find_key(reg, group, name)
    if (idx > 0) then
      if (len(reg%keys(idx)%origin) > 0) src = reg%keys(idx)%origin
    end if
  end function origin_of

  !> Where the values that a rule joins came from, for its message; `keys` lists them as
  !! 'group.key', blank-separated, the key the message names first first. The --set options
  !! among them come first: a value given on the command line is what the user just changed,
  !! and the file line of another key would show a value the rule did not see. Without one,
  !! the origin of the first key that was set, else `fallback`. Several options are joined as
  !! 'file: --set a=1, --set b=2'.
  function blame(reg, keys, fallback) result(src)
    type(registry_t), intent(in) :: reg
    character(len=*), intent(in) :: keys, fallback
    character(len=:), allocatable :: src, w, o, first
    integer :: j, idx, dot, p
    src = ''
    first = ''
    j = 1
    do
      w = word(keys, j)
      if (len(w) == 0) exit
      j = j + 1
      dot = index(w, '.')
      idx = find_key(reg, w(:dot - 1), w(dot + 1:))
      if (idx == 0) cycle
      o = reg%keys(idx)%origin
      if (len(o) == 0) cycle
      if (len(first) == 0) first = o
      p = index(o, '--set ')
      if (p == 0) cycle
      if (len(src) == 0) then
        src = o
      else if (index(src//',', o(p:)//',') == 0) then
        src = src//', '//o(p:)
      end if
    end do
    if (len(src) == 0) src = first
    if (len(src) == 0) src = fallback
  end function blame

  !> '; known groups: &a, &b, ...; did you mean &x?' for a group that is not in the registry.
  function unknown_group_hint(reg, group) result(s)
    type(registry_t), intent(in) :: reg
    character(len=*), intent(in) :: group
    character(len=:), allocatable :: s
    s = '; known groups: '//join(reg%groups, '&', '')//suggest(group, reg%groups, '&', '')
  end function unknown_group_hint

  !> For `name`, not a key of `group`: the group where it is a key if any, the keys of `group`
  !! and the closest of them.
  function unknown_key_hint(reg, group, name) result(s)
    type(registry_t), intent(in) :: reg
    character(len=*), intent(in) :: group, name
    character(len=:), allocatable :: s, keys
    integer :: j
    s = ''
    do j = 1, size(reg%keys)
      if (reg%keys(j)%name == name) s = ' ('//name//' is a key of &'//reg%keys(j)%group//')'
    end do
    keys = group_keys(reg, group)
    s = s//'; keys of &'//group//': '//join(keys, '', '')//suggest(name, keys, '''', '''')
  end function unknown_key_hint

  ! ---------------------------------------------------------------- checks

  !> Check the current value of key `k` against its range or choices. `fallback` names the
  !! source when the key was never assigned (a default).
  subroutine check_key(k, fallback, err)
    type(key_t), intent(in) :: k
    character(len=*), intent(in) :: fallback
    character(len=:), allocatable, intent(out) :: err
    character(len=:), allocatable :: src, tail
    integer :: j
    err = ''
    src = fallback
    if (len(k%origin) > 0) src = k%origin
    tail = '; allowed: '//allowed_text(k)//' ('//k%meaning//')'
    select case (k%kind)
    case (KEY_REAL)
      if (k%n == 0) then
        if (.not. in_range(k, k%r)) &
          err = src//': &'//k%group//' '//k%name//' = '//fmt_real(k%r)//' is out of range'//tail
      else
        do j = 1, k%n
          if (.not. in_range(k, k%ra(j))) then
            err = src//': &'//k%group//' '//k%name//'('//itoa(j)//') = '// &
                  fmt_real(k%ra(j))//' is out of range'//tail
            return
          end if
        end do
      end if
    case (KEY_INTEGER)
      if (.not. in_range(k, real(k%i, wp))) &
        err = src//': &'//k%group//' '//k%name//' = '//itoa(k%i)//' is out of range'//tail
    case (KEY_CHOICE)
      if (k%n == 0) then
        call check_choice(k%name, k%s)
      else
        do j = 1, k%n
          call check_choice(k%name//'('//itoa(j)//')', k%sa(j)%s)
          if (len(err) > 0) return
        end do
      end if
    end select
  contains
    subroutine check_choice(elem, x)
      character(len=*), intent(in) :: elem, x
      if (word_index(k%choices, trim(x)) == 0) &
        err = src//': &'//k%group//' '//elem//' = '''//trim(x)//''' is not one of '// &
              join(k%choices, '''', '''')//suggest(trim(x), k%choices, '''', '''')//' ('// &
              k%meaning//')'
    end subroutine check_choice
  end subroutine check_key

  pure logical function in_range(k, x)
    type(key_t), intent(in) :: k
    real(wp), intent(in) :: x
    in_range = .true.
    if (k%zero_ok .and. abs(x) <= 0.0_wp) return ! exactly 0
    if (k%auto_ok .and. x == -1.0_wp) return ! exactly -1
    if (k%has_lo) in_range = in_range .and. merge(x > k%lo, x >= k%lo, k%lo_open)
    if (k%has_hi) in_range = in_range .and. merge(x < k%hi, x <= k%hi, k%hi_open)
  end function in_range

  ! ---------------------------------------------------------------- text forms

  !> The key's current value as namelist text (reals round-trip exactly).
  function value_text(k) result(s)
    type(key_t), intent(in) :: k
    character(len=:), allocatable :: s
    integer :: j, n
    select case (k%kind)
    case (KEY_REAL)
      if (k%n == 0) then
        s = fmt_real(k%r)
      else
        n = 0
        call append_text(s, n, fmt_real(k%ra(1)))
        do j = 2, k%n
          call append_text(s, n, ', '//fmt_real(k%ra(j)))
        end do
        s = s(:n)
      end if
    case (KEY_INTEGER)
      s = itoa(k%i)
    case (KEY_LOGICAL)
      s = merge('.true. ', '.false.', k%l)
      s = trim(s)
    case default
      if (k%n == 0) then
        s = quoted(trim(k%s))
      else
        n = 0
        call append_text(s, n, quoted(trim(k%sa(1)%s)))
        do j = 2, k%n
          call append_text(s, n, ', '//quoted(trim(k%sa(j)%s)))
        end do
        s = s(:n)
      end if
    end select
  end function value_text

  !> The most characters a string or choice key (or each element of an array of choices) holds.
  pure integer function text_length(k)
    type(key_t), intent(in) :: k
    if (k%n > 0) then
      text_length = len(k%sa(1)%s)
    else
      text_length = len(k%s)
    end if
  end function text_length

  !> What the key accepts, e.g. '0.5 < tau <= 10', 'one of ''mrt'', ''bgk'''.
  function allowed_text(k) result(s)
    type(key_t), intent(in) :: k
    character(len=:), allocatable :: s, nm
    nm = k%name
    if (k%n > 0) nm = k%name//'(i)'
    select case (k%kind)
    case (KEY_REAL, KEY_INTEGER)
      if (k%has_lo .and. k%has_hi) then
        s = bound(k, k%lo)//merge(' < ', ' <=', k%lo_open)//' '//nm// &
            merge(' < ', ' <=', k%hi_open)//' '//bound(k, k%hi)
      else if (k%has_lo) then
        s = nm//merge(' > ', ' >=', k%lo_open)//' '//bound(k, k%lo)
      else if (k%has_hi) then
        s = nm//merge(' < ', ' <=', k%hi_open)//' '//bound(k, k%hi)
      else
        s = 'any'
      end if
      s = squeeze(s)
      if (k%zero_ok) s = nm//' = 0 or '//s
      if (k%auto_ok) s = nm//' = -1 or '//s
    case (KEY_LOGICAL)
      s = '.true. or .false.'
    case (KEY_CHOICE)
      s = 'one of '//join(k%choices, '''', '''')
    case default
      s = 'text of at most '//itoa(text_length(k))//' characters'
    end select
  end function allowed_text

  function bound(k, x) result(s)
    type(key_t), intent(in) :: k
    real(wp), intent(in) :: x
    character(len=:), allocatable :: s
    if (k%kind == KEY_INTEGER) then
      s = itoa(nint(x))
    else
      s = fmt_real(x)
      if (len(s) > 2) then
        if (s(len(s) - 1:) == '.0') s = s(:len(s) - 2) ! a bound reads better as 10 than 10.0
      end if
    end if
  end function bound

  !> 'real', 'integer', 'logical', 'string' or 'choice'.
  function type_name(k) result(s)
    type(key_t), intent(in) :: k
    character(len=:), allocatable :: s
    select case (k%kind)
    case (KEY_REAL)
      s = 'real'
    case (KEY_INTEGER)
      s = 'integer'
    case (KEY_LOGICAL)
      s = 'logical'
    case (KEY_STRING)
      s = 'string'
    case default
      s = 'choice'
    end select
  end function type_name

  !> Collapse runs of blanks to one (used to tidy range texts built from fixed pieces).
  function squeeze(t) result(s)
    character(len=*), intent(in) :: t
    character(len=:), allocatable :: s
    integer :: j
    s = ''
    do j = 1, len_trim(t)
      if (t(j:j) == ' ' .and. len(s) > 0) then
        if (s(len(s):) == ' ') cycle
      end if
      s = s//t(j:j)
    end do
  end function squeeze

  !> The keys of group `g`, blank-separated.
  function group_keys(reg, g) result(s)
    type(registry_t), intent(in) :: reg
    character(len=*), intent(in) :: g
    character(len=:), allocatable :: s
    integer :: j
    s = ''
    do j = 1, size(reg%keys)
      if (reg%keys(j)%group == g) s = trim(adjustl(s//' '//reg%keys(j)%name))
    end do
  end function group_keys

  !> Word `i` of blank-separated `list` ('' past the end).
  function word(list, i) result(w)
    character(len=*), intent(in) :: list
    integer, intent(in) :: i
    character(len=:), allocatable :: w
    integer :: p, q, j
    w = ''
    p = 1
    q = 0
    do j = 1, i
      p = q + verify(list(q + 1:), ' ')
      if (p == q) return
      q = p - 1 + index(list(p:)//' ', ' ') - 1
    end do
    w = list(p:q)
  end function word

  !> Position of `w` among the words of `list`, 0 if absent.
  integer function word_index(list, w) result(idx)
    character(len=*), intent(in) :: list, w
    idx = 1
    do while (len(word(list, idx)) > 0)
      if (word(list, idx) == w) return
      idx = idx + 1
    end do
    idx = 0
  end function word_index

  !> The words of `list` joined by ', ', each between `pre` and `post`.
  function join(list, pre, post) result(s)
    character(len=*), intent(in) :: list, pre, post
    character(len=:), allocatable :: s
    integer :: j
    s = ''
    j = 1
    do while (len(word(list, j)) > 0)
      if (j > 1) s = s//', '
      s = s//pre//word(list, j)//post
      j = j + 1
    end do
  end function join

  !> '; did you mean <pre>x<post>?' for the word of `list` closest to `w` by edit distance, if
  !! it is close enough to be a likely misspelling; '' otherwise.
  function suggest(w, list, pre, post) result(s)
    character(len=*), intent(in) :: w, list, pre, post
    character(len=:), allocatable :: s
    integer :: j, d, best
    s = ''
    best = max(2, (len(w) + 1)/2) + 1
    j = 1
    do while (len(word(list, j)) > 0)
      d = edit_distance(w, word(list, j))
      if (d < best) then
        best = d
        s = '; did you mean '//pre//word(list, j)//post//'?'
      end if
      j = j + 1
    end do
  end function suggest

  !> Levenshtein distance: insertions, deletions and substitutions needed to turn a into b.
  pure integer function edit_distance(a, b) result(d)
    character(len=*), intent(in) :: a, b
    integer :: prev(0:len(b)), row(0:len(b)), i, j
    prev = [(j, j=0, len(b))]
    do i = 1, len(a)
      row(0) = i
      do j = 1, len(b)
        row(j) = min(prev(j) + 1, row(j - 1) + 1, prev(j - 1) + merge(0, 1, a(i:i) == b(j:j)))
      end do
      prev = row
    end do
    d = prev(len(b))
  end function edit_distance

end module dkt_registry

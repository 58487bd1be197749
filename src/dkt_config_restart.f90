!> The input a run resumes with (--restart) against the input its checkpoint was written with
!> (/given, dkt_checkpoint). Both are read through the key registry into configurations as
!> given, before &pair, &window and lbm.cells_per_diameter are expanded, and compared key by
!> key: arrays element by element, reals as the values they read to (1.0 and 1. are equal).
!>
!> A resumed run continues the physics it started with. The keys of FREE_KEYS (run length,
!> output, checkpoints, progress, guards, wall-time and memory limits) do not change what a step
!> computes and may differ; any other difference stops every rank before a file is touched,
!> unless run.restart_changes names its key: then it is allowed, and recorded in the run file
!> (docs/running.md, "Restart").
module dkt_config_restart
  use dkt_errors, only: fatal_all, warn
  use dkt_config, only: config_t, config_load, config_registry, particles_allocate
  use dkt_registry, only: registry_t, key_t, KEY_REAL, KEY_INTEGER, KEY_LOGICAL, find_key, &
                          value_text
  use dkt_text, only: fmt_real, quoted, itoa, lower_case
  use dkt_namelist, only: parse_namelist
  implicit none
  private
  public :: input_change_t, input_changes, restart_input_check, restart_changes_problem, &
            is_free_key, FREE_KEYS

  !> The keys a restart may change without run.restart_changes, as 'group.key' or '&group'
  !! (every key of the group), blank-separated. None of them changes what a step computes:
  !! the run length and the wall-time, memory and guard limits decide when the run stops; the
  !! output, checkpoint and progress keys what it writes; lbm.streaming and the balance keys
  !! (where the slab borders lie) give the same results to the bit.
  character(len=*), parameter :: FREE_KEYS = 'run.t_end run.steps run.progress_every '// &
                                 'run.guard_every run.mach_limit '// &
                                 'run.particle_speed_limit run.checkpoint_every '// &
                                 'run.checkpoint_wall run.checkpoint_keep '// &
                                 'run.wall_limit run.memory_limit run.balance_every '// &
                                 'run.balance_threshold '// &
                                 'run.restart_changes lbm.streaming &output'

  !> the most changes one message lists; the others are counted
  integer, parameter :: LISTED = 20

  !> One value that differs between two inputs.
  type :: input_change_t
    character(len=:), allocatable :: key  !! 'group.key', 'group.key(i)' for element i
    character(len=:), allocatable :: name !! 'group.key' (the key of an element)
    character(len=:), allocatable :: was  !! the stored value, as namelist text
    character(len=:), allocatable :: now  !! the new value, as namelist text
  end type input_change_t

contains

  !> Every value in which the input of `cfg` (read by config_load) differs from the namelist
  !! text `stored`, in the order of the registry. err is '' unless `stored` cannot be read by
  !! this version (`label` names it in the message); `changes` is then empty.
  subroutine input_changes(cfg, stored, label, changes, err)
    type(config_t), intent(in) :: cfg
    character(len=*), intent(in) :: stored, label
    type(input_change_t), allocatable, intent(out) :: changes(:)
    character(len=:), allocatable, intent(out) :: err
    type(config_t) :: was
    type(config_t), target :: a, b
    type(registry_t) :: ra, rb
    character(len=8) :: no_sets(0)
    integer :: n, j
    n = 0
    allocate (changes(16))
    err = ''
    if (stored /= cfg%given) then
      ! config_load gives the stored input in the form of cfg%given (every key, this version's)
      ! and the size of its particle arrays
      call config_load(was, stored, label, no_sets, err)
      if (len(err) == 0) then
        j = max(size(cfg%particles%diameter), size(was%particles%diameter))
        call particles_allocate(a%particles, j)
        call particles_allocate(b%particles, j)
        call config_registry(a, ra)
        call config_registry(b, rb)
        call parse_namelist(ra, was%given, label, err)
        if (len(err) == 0) call parse_namelist(rb, cfg%given, cfg%file, err)
      end if
      if (len(err) == 0) then
        do j = 1, size(ra%keys)
          call compare(ra%keys(j), rb%keys(j))
        end do
      end if
    end if
    changes = changes(:n)
  contains
    subroutine compare(ka, kb)
      type(key_t), intent(in) :: ka, kb
      character(len=:), allocatable :: name
      integer :: e
      name = ka%group//'.'//ka%name
      select case (ka%kind)
      case (KEY_REAL)
        if (ka%n == 0) then
          if (ka%r /= kb%r) call push(name, name, fmt_real(ka%r), fmt_real(kb%r))
        else
          do e = 1, ka%n
            if (ka%ra(e) /= kb%ra(e)) call push(name//'('//itoa(e)//')', name, &
                                                fmt_real(ka%ra(e)), fmt_real(kb%ra(e)))
          end do
        end if
      case (KEY_INTEGER)
        if (ka%i /= kb%i) call push(name, name, value_text(ka), value_text(kb))
      case (KEY_LOGICAL)
        if (ka%l .neqv. kb%l) call push(name, name, value_text(ka), value_text(kb))
      case default ! a string or a choice
        if (ka%n == 0) then
          if (trim(ka%s) /= trim(kb%s)) call push(name, name, value_text(ka), value_text(kb))
        else
          do e = 1, ka%n
            if (trim(ka%sa(e)%s) /= trim(kb%sa(e)%s)) &
              call push(name//'('//itoa(e)//')', name, quoted(trim(ka%sa(e)%s)), &
                        quoted(trim(kb%sa(e)%s)))
          end do
        end if
      end select
    end subroutine compare

    !> Append one change, doubling the list when it is full (a moved array of 10^4
    !! particles is 10^4 changes).
    subroutine push(key, name, old, new)
      character(len=*), intent(in) :: key, name, old, new
      type(input_change_t), allocatable :: more(:)
      if (n == size(changes)) then
        allocate (more(2*n))
        more(:n) = changes
        call move_alloc(more, changes)
      end if
      n = n + 1
      changes(n) = input_change_t(key, name, old, new)
    end subroutine push
  end subroutine input_changes

  !> Is 'group.key' a key a restart may change freely (FREE_KEYS)?
  pure logical function is_free_key(name) result(free)
    character(len=*), intent(in) :: name
    integer :: dot
    dot = index(name, '.')
    free = index(' '//FREE_KEYS//' ', ' '//name//' ') > 0
    if (dot > 0) free = free .or. index(' '//FREE_KEYS//' ', ' &'//name(:dot - 1)//' ') > 0
  end function is_free_key

  !> Before a run resumes from the checkpoint `path`: compare the input of `cfg` with the one
  !! the checkpoint holds (`stored`, its /given). Changes of keys outside FREE_KEYS that
  !! run.restart_changes does not name stop every rank (all hold the same texts) with one
  !! message naming the checkpoint, each key and both values, and how to allow it. `record`
  !! lists the allowed ones as 'group.key old -> new; ...' for the run file ('' if none). A
  !! checkpoint without a readable input (an earlier version's) gives a warning.
  subroutine restart_input_check(cfg, stored, path, record)
    type(config_t), intent(in) :: cfg
    character(len=*), intent(in) :: stored, path
    character(len=:), allocatable, intent(out) :: record
    type(input_change_t), allocatable :: changes(:)
    character(len=:), allocatable :: err, refused, keys, allowed
    integer :: j, nref
    record = ''
    if (len_trim(stored) == 0) then
      call warn('--restart '//path//': the checkpoint holds no input of the run that wrote '// &
                'it (written by an earlier version): a change of the physics goes unnoticed')
      return
    end if
    call input_changes(cfg, stored, path//' (/given)', changes, err)
    if (len(err) > 0) then
      call warn('--restart '//path//': the input stored in the checkpoint cannot be read by '// &
                'this version ('//err//'): a change of the physics goes unnoticed')
      return
    end if
    allowed = ' '//words(cfg%run%restart_changes)//' '
    refused = ''
    keys = ''
    nref = 0
    do j = 1, size(changes)
      associate (c => changes(j))
        if (is_free_key(c%name)) cycle
        if (index(allowed, ' '//c%name//' ') > 0) then
          if (len(record) > 0) record = record//'; '
          record = record//c%key//' '//c%was//' -> '//c%now
          cycle
        end if
        nref = nref + 1
        if (nref <= LISTED) refused = refused//'; '//c%key//' = '//c%was// &
                                      ' in the checkpoint, '//c%now//' now'
        if (index(keys//',', ', '//c%name//',') == 0) keys = keys//', '//c%name
      end associate
    end do
    if (nref == 0) return
    if (nref > LISTED) refused = refused//'; and '//itoa(nref - LISTED)//' more'
    call fatal_all(trim(cfg%file)//': --restart '//path//': the input changes '// &
                   'what the checkpoint''s run computes: '//refused(3:)//'. A resumed run '// &
                   'continues the physics it started with: resume with the input of the '// &
                   'run that wrote the checkpoint, or allow the change with --set '// &
                   'run.restart_changes='''//keys(3:)//''' (it is then recorded in the '// &
                   'run file)')
  end subroutine restart_input_check

  !> What is wrong with run.restart_changes of `cfg` ('' if nothing): each of its words must
  !! be an input key 'group.key'.
  function restart_changes_problem(cfg) result(err)
    type(config_t), intent(in) :: cfg
    character(len=:), allocatable :: err
    type(config_t), target :: c
    type(registry_t) :: reg
    character(len=:), allocatable :: list, w
    integer :: a, b, dot
    err = ''
    list = words(cfg%run%restart_changes)
    if (len(list) == 0) return
    c = cfg
    call config_registry(c, reg)
    a = 1
    do while (a <= len(list))
      b = index(list(a:)//' ', ' ') + a - 1
      w = list(a:b - 1)
      a = b + 1
      dot = index(w, '.')
      if (dot > 1) then
        if (find_key(reg, w(:dot - 1), w(dot + 1:)) > 0) cycle
      end if
      err = trim(cfg%file)//': run.restart_changes = '//quoted(trim(cfg%run%restart_changes))// &
            ': '//quoted(w)//' is not an input key; allowed: input keys as group.key '// &
            'separated by commas, e.g. ''pair.density, particles.gravity'' (input/README.md)'
      return
    end do
  end function restart_changes_problem

  !> The entries of a list separated by commas or blanks, lower case, one blank between.
  function words(list) result(s)
    character(len=*), intent(in) :: list
    character(len=:), allocatable :: s
    character(len=len(list)) :: t
    integer :: j
    t = lower_case(list)
    do j = 1, len(t)
      if (t(j:j) == ',' .or. iachar(t(j:j)) == 9) t(j:j) = ' '
    end do
    s = ''
    j = 1
    do while (j <= len_trim(t))
      if (t(j:j) /= ' ' .or. (len(s) > 0 .and. s(len(s):) /= ' ')) s = s//t(j:j)
      j = j + 1
    end do
    s = trim(s)
  end function words

end module dkt_config_restart

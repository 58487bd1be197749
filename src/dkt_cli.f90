!> The command line of dktlbm (FILE, --set, --restart, --check, --print-defaults, --help,
!> --version), the help text, and reading the scene file whole.
module dkt_cli
  use dkt_text, only: itoa, append_text
  use dkt_config_types, only: config_groups
  implicit none
  private
  public :: parse_command_line, parse_arguments, read_text_file, print_help

  !> The command line: dktlbm FILE [--set g.k=v ...] [--check] [--print-defaults] [--help]
  !! [--version].
  type, public :: cli_t
    character(len=:), allocatable :: nml_file        !! the namelist file; '' if none was given
    character(len=512), allocatable :: overrides(:)  !! 'group.key=value', in the given order
    logical :: check = .false.
    logical :: print_defaults = .false.
    logical :: help = .false.
    logical :: version = .false.
    character(len=:), allocatable :: restart         !! checkpoint to resume from; '' = none
  end type cli_t

  character(len=*), parameter :: USAGE = 'usage: dktlbm FILE [--set group.key=value ...] '// &
                                 '[--restart CHECKPOINT] [--check] [--print-defaults] '// &
                                 '[--help] [--version]'
  character(len=*), parameter :: OPTIONS = '--set group.key=value, --set=group.key=value, '// &
                                 '--restart CHECKPOINT, --check, --print-defaults, --help, '// &
                                 '--version'
  character(len=*), parameter :: RESTART_NEEDS = 'option --restart needs a checkpoint file: '// &
                                 '--restart runs/case1/case1_chk_000010000.h5'
  character(len=*), parameter :: NL = new_line('a')

contains

  !> Read the command line of the program into `cli` (see parse_arguments).
  subroutine parse_command_line(cli, err)
    type(cli_t), intent(out) :: cli
    character(len=:), allocatable, intent(out) :: err
    integer :: j, n, length, longest
    n = command_argument_count()
    longest = 1
    do j = 1, n
      call get_command_argument(j, length=length)
      longest = max(longest, length)
    end do
    block
      character(len=longest) :: args(n)
      do j = 1, n
        call get_command_argument(j, args(j))
      end do
      call parse_arguments(args, cli, err)
    end block
  end subroutine parse_command_line

  !> Interpret the arguments `args` (without the program name):
  !! FILE [--set g.k=v | --set=g.k=v ...] [--check] [--print-defaults] [--help] [--version].
  !! A FILE is needed unless --help, --version or --print-defaults is given.
  subroutine parse_arguments(args, cli, err)
    character(len=*), intent(in) :: args(:)
    type(cli_t), intent(out) :: cli
    character(len=:), allocatable, intent(out) :: err
    character(len=:), allocatable :: arg
    integer :: j, n
    err = ''
    cli%nml_file = ''
    cli%restart = ''
    ! room for every --set at once (an argument is at most one), trimmed at the end: appending
    ! one by one would copy the list at each, quadratic in the number of options
    allocate (cli%overrides(count(args == '--set') + count(index(args, '--set=') == 1)))
    n = 0
    j = 0
    do while (j < size(args))
      j = j + 1
      arg = trim(args(j))
      select case (arg)
      case ('--set')
        if (j == size(args)) then
          err = 'option --set needs a value: --set group.key=value, e.g. --set lbm.tau=0.7'
          return
        end if
        j = j + 1
        call add_override(trim(args(j)))
      case ('--restart')
        if (j == size(args)) then
          err = RESTART_NEEDS
          return
        end if
        j = j + 1
        cli%restart = trim(args(j))
        ! an empty value (--restart '') would otherwise start a fresh run, and an option
        ! (--restart --set output.dir=X) would be taken for the checkpoint's path
        if (len(cli%restart) == 0) err = RESTART_NEEDS
        if (index(cli%restart, '--') == 1) &
          err = RESTART_NEEDS//' (in ''--restart '//cli%restart//''' the option '''// &
                cli%restart//''' stands where the file should)'
      case ('--check')
        cli%check = .true.
      case ('--print-defaults')
        cli%print_defaults = .true.
      case ('--help', '-h')
        cli%help = .true.
      case ('--version')
        cli%version = .true.
      case default
        if (index(arg, '--set=') == 1) then
          call add_override(arg(7:))
        else if (index(arg, '--restart=') == 1) then
          cli%restart = arg(11:)
          if (len(cli%restart) == 0) err = RESTART_NEEDS
        else if (index(arg, '-') == 1 .and. len(arg) > 1) then
          err = 'unknown option '''//arg//'''; options: '//OPTIONS//NL//USAGE
        else if (len(cli%nml_file) > 0) then
          err = 'more than one namelist file: '''//cli%nml_file//''' and '''//arg//''''// &
                NL//USAGE
        else
          cli%nml_file = arg
        end if
      end select
      if (len(err) > 0) return
    end do
    if (n < size(cli%overrides)) cli%overrides = cli%overrides(1:n)
    if (len(cli%nml_file) == 0 .and. .not. (cli%help .or. cli%version .or. cli%print_defaults)) &
      err = 'no namelist file given'//NL//USAGE//NL//'see dktlbm --help'
  contains
    subroutine add_override(spec)
      character(len=*), intent(in) :: spec
      if (len(spec) > len(cli%overrides)) then
        err = 'option --set '//spec(:40)//'... is longer than '//itoa(len(cli%overrides))// &
              ' characters'
      else if (index(spec, '=') == 0 .or. index(spec, '.') == 0) then
        err = 'option --set '//spec//': expected --set group.key=value, e.g. --set lbm.tau=0.7'
      else
        n = n + 1
        cli%overrides(n) = spec
      end if
    end subroutine add_override
  end subroutine parse_arguments

  !> Read the file `path` whole into `text`, newlines kept.
  subroutine read_text_file(path, text, err)
    character(len=*), intent(in) :: path
    character(len=:), allocatable, intent(out) :: text
    character(len=:), allocatable, intent(out) :: err
    character(len=256) :: msg
    logical :: exists
    integer :: unit, ios, nbytes
    err = ''
    text = ''
    inquire (file=path, exist=exists)
    if (.not. exists) then
      err = 'cannot open namelist file '''//path//''': no such file'
      return
    end if
    open (newunit=unit, file=path, access='stream', form='unformatted', action='read', &
          status='old', iostat=ios, iomsg=msg)
    if (ios /= 0) then
      err = 'cannot open namelist file '''//path//''': '//trim(msg)
      return
    end if
    inquire (unit=unit, size=nbytes)
    if (nbytes > 0) then
      deallocate (text)
      allocate (character(len=nbytes) :: text)
      read (unit, iostat=ios, iomsg=msg) text
    else
      ! no size: a pipe (/dev/stdin, <(...)) or an empty file; read to its end
      call read_to_end(ios)
    end if
    if (ios /= 0) err = 'cannot read namelist file '''//path//''': '//trim(msg)
    close (unit)
  contains
    !> text = every byte up to the end of the unit (append_text: linear time).
    subroutine read_to_end(ios)
      integer, intent(out) :: ios
      character(len=:), allocatable :: buffer
      character(len=1) :: c
      integer :: n
      n = 0
      call append_text(buffer, n, '')
      do
        read (unit, iostat=ios, iomsg=msg) c
        if (ios /= 0) exit
        call append_text(buffer, n, c)
      end do
      if (is_iostat_end(ios)) ios = 0
      text = buffer(1:n)
    end subroutine read_to_end
  end subroutine read_text_file

  !> Usage, options and a word on the input, to `unit`.
  subroutine print_help(unit)
    integer, intent(in) :: unit
    character(len=:), allocatable :: groups
    groups = config_groups()
    write (unit, '(a)') USAGE, &
      '       mpirun -n N dktlbm FILE ...', &
      '', &
      'Particles settling in a 2-D channel, D2Q9 lattice Boltzmann (MRT), on MPI ranks.', &
      '', &
      'options:', &
      '  FILE                   the scene: a namelist file, e.g. input/case1.nml', &
      '  --set group.key=value  set one key after FILE is read (also --set=group.key=value);', &
      '                         repeatable; array elements as key(2)=value; strings need no', &
      '                         quotes, e.g. --set lbm.tau=0.7 --set output.dir=/tmp/run', &
      '  --restart CHECKPOINT   resume the run from a checkpoint file it wrote (same FILE', &
      '                         and --set options; any number of ranks); the output continues', &
      '  --check                validate, print the derived lattice parameters and exit;', &
      '                         no lattice is allocated. Exits non-zero for whatever the', &
      '                         run would refuse (memory, an earlier run''s files in', &
      '                         output.dir). With --restart the checkpoint is not read', &
      '  --print-defaults       print every key with its default, unit, allowed values and', &
      '                         meaning, as a namelist file, and exit; with FILE (and', &
      '                         --set) the values they give instead of the defaults', &
      '  --help                 print this help and exit', &
      '  --version              print the version and exit', &
      '', &
      'The input file holds namelist groups in physical units (cm, g, s):', &
      '  '//groups, &
      'A group starts with &name, holds key = value items separated by commas or newlines,', &
      'and ends with /; ! starts a comment. A key not given keeps its default. An invalid', &
      'key or value stops the run with a message naming the file, line, group, key, value', &
      'and what is allowed. All keys: dktlbm --print-defaults, or input/README.md.'
  end subroutine print_help

end module dkt_cli

!> The little the code needs from the file system that Fortran does not offer: creating a
!> directory path (POSIX mkdir through C interoperability), testing for existence, renaming a
!> file in one step (POSIX rename: a reader sees the old file or the new one, never a part),
!> deleting one, reserving the space a file will need (POSIX posix_fallocate), and holding a
!> lock file while the process lives (POSIX flock).
module dkt_filesystem
  use iso_c_binding, only: c_char, c_int, c_null_char, c_long, c_ptr, c_f_pointer, &
                           c_associated, c_size_t
  implicit none
  private
  public :: make_directories, path_exists, rename_file, remove_file, write_marker
  public :: directory_problem, reserve_space, space_problem, lock_take, lock_release, &
            lock_held, process_id

  integer(c_int), parameter :: O_WRONLY = 1 !! open(2) flag (Linux, BSD, macOS)
  integer(c_int), parameter :: O_RDWR = 2   !! open(2) flag (Linux, BSD, macOS)
  !> flock(2) operations (Linux, BSD, macOS): exclusive, without waiting
  integer(c_int), parameter :: LOCK_EX = 2, LOCK_NB = 4

  interface
    integer(c_int) function c_mkdir(path, mode) bind(C, name='mkdir')
      import :: c_char, c_int
      character(kind=c_char), intent(in) :: path(*)
      integer(c_int), value :: mode
    end function c_mkdir
    integer(c_int) function c_rename(old, new) bind(C, name='rename')
      import :: c_char, c_int
      character(kind=c_char), intent(in) :: old(*), new(*)
    end function c_rename
    integer(c_int) function c_access(path, mode) bind(C, name='access')
      import :: c_char, c_int
      character(kind=c_char), intent(in) :: path(*)
      integer(c_int), value :: mode
    end function c_access
    integer(c_int) function c_open(path, flags) bind(C, name='open')
      import :: c_char, c_int
      character(kind=c_char), intent(in) :: path(*)
      integer(c_int), value :: flags
    end function c_open
    integer(c_int) function c_close(fd) bind(C, name='close')
      import :: c_int
      integer(c_int), value :: fd
    end function c_close
    integer(c_int) function c_flock(fd, operation) bind(C, name='flock')
      import :: c_int
      integer(c_int), value :: fd, operation
    end function c_flock
    integer(c_int) function c_ftruncate(fd, length) bind(C, name='ftruncate')
      import :: c_int, c_long
      integer(c_int), value :: fd
      integer(c_long), value :: length
    end function c_ftruncate
    integer(c_long) function c_write(fd, buf, count) bind(C, name='write')
      import :: c_int, c_long, c_char, c_size_t
      integer(c_int), value :: fd
      character(kind=c_char), intent(in) :: buf(*)
      integer(c_size_t), value :: count
    end function c_write
    integer(c_int) function c_getpid() bind(C, name='getpid')
      import :: c_int
    end function c_getpid
    !> returns the error number (0 on success), not -1 and errno
    integer(c_int) function c_posix_fallocate(fd, offset, length) bind(C, name='posix_fallocate')
      import :: c_int, c_long
      integer(c_int), value :: fd
      integer(c_long), value :: offset, length
    end function c_posix_fallocate
    type(c_ptr) function c_strerror(errnum) bind(C, name='strerror')
      import :: c_int, c_ptr
      integer(c_int), value :: errnum
    end function c_strerror
  end interface

contains

  !> Rename `old` to `new`, replacing `new` atomically; false if it failed.
  logical function rename_file(old, new)
    character(len=*), intent(in) :: old, new
    rename_file = c_rename(old//c_null_char, new//c_null_char) == 0
  end function rename_file

  !> This process's id.
  integer function process_id()
    process_id = int(c_getpid())
  end function process_id

  !> Take the lock file `path` (made if missing) for as long as this process keeps `fd` open: an
  !! exclusive flock(2), which the system releases when the process ends however it ends (a run
  !! killed leaves no stale lock). Taken: fd >= 0, and `text` (who holds it) is the file's
  !! content. Held by another process: fd = -1 and `holder` is the text it wrote. The file is
  !! never deleted (a process could lock a deleted file while another makes a new one); its
  !! content is emptied on release. err is '' unless the file cannot be made or opened.
  subroutine lock_take(path, text, fd, holder, err)
    character(len=*), intent(in) :: path, text
    integer, intent(out) :: fd
    character(len=:), allocatable, intent(out) :: holder, err
    integer :: u, ios
    integer(c_int) :: cfd
    integer(c_long) :: written
    holder = ''
    err = ''
    fd = -1
    if (.not. path_exists(path)) then
      open (newunit=u, file=path, status='unknown', action='write', iostat=ios)
      if (ios == 0) close (u)
    end if
    cfd = c_open(path//c_null_char, O_RDWR)
    if (cfd < 0) then
      err = 'cannot open the lock file '''//path//''''
      return
    end if
    if (c_flock(cfd, ior(LOCK_EX, LOCK_NB)) /= 0) then
      cfd = c_close(cfd)
      holder = first_line(path)
      return
    end if
    ! the text through the locked descriptor (closing another one would drop an emulated lock)
    ! (who holds it is for the message of a run refused; a failed write costs only that)
    if (c_ftruncate(cfd, 0_c_long) == 0) &
      written = c_write(cfd, text//new_line('a'), int(len(text) + 1, c_size_t))
    fd = int(cfd)
  end subroutine lock_take

  !> Whether another process holds the lock file `path` (lock_take), without making the file or
  !! writing to it: .false. when there is no such file or nobody holds it. `holder` is the text
  !! the holder wrote.
  logical function lock_held(path, holder) result(held)
    character(len=*), intent(in) :: path
    character(len=:), allocatable, intent(out) :: holder
    integer(c_int) :: cfd, e
    held = .false.
    holder = ''
    if (.not. path_exists(path)) return
    cfd = c_open(path//c_null_char, O_RDWR)
    if (cfd < 0) return
    held = c_flock(cfd, ior(LOCK_EX, LOCK_NB)) /= 0
    ! (closing the descriptor drops a lock taken here)
    e = c_close(cfd)
    if (held) holder = first_line(path)
  end function lock_held

  !> The first line of the text file `path` ('' if it cannot be read).
  function first_line(path) result(line)
    character(len=*), intent(in) :: path
    character(len=:), allocatable :: line
    character(len=256) :: buf
    integer :: u, ios
    line = ''
    open (newunit=u, file=path, status='old', action='read', iostat=ios)
    if (ios /= 0) return
    read (u, '(a)', iostat=ios) buf
    if (ios == 0) line = trim(buf)
    close (u)
  end function first_line

  !> Release a lock lock_take took (fd >= 0), emptying the file first.
  subroutine lock_release(fd)
    integer, intent(inout) :: fd
    integer(c_int) :: e
    if (fd < 0) return
    e = c_ftruncate(int(fd, c_int), 0_c_long)
    e = c_close(int(fd, c_int))
    fd = -1
  end subroutine lock_release

  !> Delete the file at `path` if there is one.
  subroutine remove_file(path)
    character(len=*), intent(in) :: path
    integer :: u, ios
    logical :: exists
    inquire (file=path, exist=exists)
    if (.not. exists) return
    open (newunit=u, file=path, status='old', iostat=ios)
    if (ios == 0) close (u, status='delete', iostat=ios)
  end subroutine remove_file

  !> True if a file or directory exists at path.
  logical function path_exists(path)
    character(len=*), intent(in) :: path
    inquire (file=path, exist=path_exists)
    if (.not. path_exists) inquire (file=trim(path)//'/.', exist=path_exists)
  end function path_exists

  !> Create directory path and its missing parents (like mkdir -p). err is '' on success.
  subroutine make_directories(path, err)
    character(len=*), intent(in) :: path
    character(len=:), allocatable, intent(out) :: err
    integer :: k
    integer(c_int) :: rc
    err = ''
    if (len_trim(path) == 0) then
      err = 'empty directory name'
      return
    end if
    do k = 2, len_trim(path) + 1
      if (k <= len_trim(path)) then
        if (path(k:k) /= '/') cycle
      end if
      if (path_exists(path(1:k - 1))) cycle
      rc = c_mkdir(path(1:k - 1)//c_null_char, int(o'755', c_int))
      if (rc /= 0 .and. .not. path_exists(path(1:k - 1))) then
        err = 'cannot create directory '''//path(1:k - 1)//''''
        return
      end if
    end do
    if (.not. is_directory(path)) err = ''''//trim(path)//''' exists but is not a directory'
  end subroutine make_directories

  !> Why a run could not write its files into directory `path` ('' if it could): `path`, or
  !! the nearest of its parents that exists (the run creates the others), must be a directory
  !! that this process may write into (POSIX access W_OK and X_OK).
  function directory_problem(path) result(err)
    character(len=*), intent(in) :: path
    character(len=:), allocatable :: err
    character(len=:), allocatable :: at
    integer(c_int), parameter :: W_OK = 2, X_OK = 1
    integer :: slash
    err = ''
    at = trim(path)
    do while (len(at) > 0 .and. .not. path_exists(at))
      slash = index(at, '/', back=.true.)
      if (slash == 0) then
        at = '.'
      else if (slash == 1) then
        at = '/'
      else
        at = at(:slash - 1)
      end if
    end do
    if (len(at) == 0) at = '.'
    if (.not. is_directory(at)) then
      err = ''''//at//''' exists and is not a directory'
    else if (c_access(at//c_null_char, ior(W_OK, X_OK)) /= 0) then
      err = 'the directory '''//at//''' is not writable'
    end if
    if (len(err) > 0 .and. at /= trim(path)) err = 'cannot create it: '//err
  end function directory_problem

  logical function is_directory(path)
    character(len=*), intent(in) :: path
    inquire (file=trim(path)//'/.', exist=is_directory)
  end function is_directory

  !> A one-line text file (rank-local), for batch scripts: replaced atomically. False when it
  !! could not be written (the caller stops the run: the scripts would act on a stale marker).
  logical function write_marker(path, text) result(ok)
    character(len=*), intent(in) :: path, text
    integer :: u, ios
    ok = .false.
    open (newunit=u, file=path//'.tmp', status='replace', action='write', iostat=ios)
    if (ios /= 0) return
    write (u, '(a)', iostat=ios) text
    if (ios /= 0) then
      close (u, status='delete', iostat=ios)
      return
    end if
    close (u, iostat=ios)
    if (ios /= 0) return
    ok = rename_file(path//'.tmp', path)
    if (.not. ok) call remove_file(path//'.tmp')
  end function write_marker

  !> Create the file `path` holding `bytes` bytes of allocated space, so that a write of that
  !! size cannot then fail for want of space. err is '' on success, else the system's reason
  !! ("No space left on device"); the file is removed then. A file system that cannot reserve
  !! space (EINVAL, EOPNOTSUPP) is not an error: the write itself will tell.
  subroutine reserve_space(path, bytes, err)
    character(len=*), intent(in) :: path
    integer(c_long), intent(in) :: bytes
    character(len=:), allocatable, intent(out) :: err
    integer(c_int), parameter :: EINVAL = 22, EOPNOTSUPP = 95
    integer :: u, ios
    integer(c_int) :: fd, rc
    character(len=256) :: msg
    err = ''
    open (newunit=u, file=path, status='replace', action='write', iostat=ios, iomsg=msg)
    if (ios /= 0) then
      err = trim(msg)
      return
    end if
    close (u)
    fd = c_open(path//c_null_char, O_WRONLY)
    if (fd < 0) then
      err = 'cannot open it'
    else
      rc = c_posix_fallocate(fd, 0_c_long, bytes)
      if (rc /= 0 .and. rc /= EINVAL .and. rc /= EOPNOTSUPP) err = system_reason(rc)
      if (c_close(fd) /= 0 .and. len(err) == 0) err = 'cannot close it'
    end if
    if (len(err) > 0) call remove_file(path)
  end subroutine reserve_space

  !> Whether `bytes` bytes fit in the directory `dir` now: '' if they do (or the file system
  !! cannot say), else the system's reason. The space is reserved in a file <dir>/<probe> that
  !! is removed again.
  function space_problem(dir, probe, bytes) result(err)
    character(len=*), intent(in) :: dir, probe
    integer(c_long), intent(in) :: bytes
    character(len=:), allocatable :: err
    call reserve_space(dir//'/'//probe, bytes, err)
    call remove_file(dir//'/'//probe)
  end function space_problem

  !> The system's text for error number `errnum` (strerror).
  function system_reason(errnum) result(text)
    integer(c_int), intent(in) :: errnum
    character(len=:), allocatable :: text
    character(kind=c_char), pointer :: c(:)
    type(c_ptr) :: p
    integer :: n
    character(len=12) :: digits
    write (digits, '(i0)') errnum
    text = 'error number '//trim(digits)
    p = c_strerror(errnum)
    if (.not. c_associated(p)) return
    call c_f_pointer(p, c, [256])
    n = 0
    do while (n < 256)
      if (c(n + 1) == c_null_char) exit
      n = n + 1
    end do
    deallocate (text)
    allocate (character(len=n) :: text)
    text = transfer(c(1:n), text)
  end function system_reason

end module dkt_filesystem

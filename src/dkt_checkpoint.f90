!> Checkpoint files: everything a run needs to continue bit for bit, in one parallel HDF5 file
!> `<dir>/<name>_chk_<step>.h5` (docs/design.md, "Output"), as datasets:
!>
!> - /f: the populations of every node (h5py shape (9, ny, nx)), written and read by rows, so
!>   a run may resume on another number of ranks;
!> - /state_int: step, window shift, series samples written so far, nx, ny, number of
!>   particles, number of episodes, in_episode (0/1), length of /given;
!> - /state_real: dx, dt (to refuse a checkpoint of another lattice or time step);
!> - /particles (h5py (n, 10)): x, y, u, v, omega, fx, fy, torque, cx, cy in lattice units;
!> - /episodes (h5py (3, n_episodes)): start, end and smallest gap of the episodes so far;
!> - /given: the input as read, as character codes, for the record;
!> - /precision: how the populations are stored (lbm.precision): 0 'double', 1 'single' (f_i - w_i
!>   in 4 bytes), 2 'single_unshifted'; absent in checkpoints written before single storage
!>   existed, which are 'double'. /f holds the stored values exactly (a 4-byte value converts
!>   to 8 bytes and back without change), so a single-precision run resumes bit for bit too.
!>
!> A checkpoint is written to `<file>.tmp` and renamed when complete, so a failed write (disk
!> full, directory gone) never damages the previous checkpoint. A checkpoint is read only after
!> its sizes and counts passed the checks of checkpoint_read (against the datasets' shapes, the
!> scene and sane bounds), so a damaged file is refused before anything is allocated from it.
!> The HDF5 calls are dkt_io's.
module dkt_checkpoint
  use mpi_f08, only: MPI_Comm, MPI_LOGICAL, MPI_LOR, MPI_Allreduce, MPI_Bcast, MPI_Comm_rank
  use hdf5, only: hsize_t
  use ieee_arithmetic, only: ieee_is_finite
  use dkt_kinds, only: wp, sp
  use dkt_store, only: lattice_t, lattice_precision_name
  use dkt_filesystem, only: rename_file
  use dkt_registry, only: itoa
  ! the most particles a scene may hold: a count above it in a checkpoint is a damaged file
  use dkt_config, only: MAX_PARTICLES
  use dkt_io, only: io_file_t, io_file_open, io_file_close, io_put_real, &
                    io_put_int, io_get_real, io_get_int, io_dataset_dims
  implicit none
  private
  public :: checkpoint_t, checkpoint_write, checkpoint_read, checkpoint_name, NSTATE, &
            STORAGE_NAMES

  !> lbm.precision by its code in /precision (0, 1, 2)
  character(len=16), parameter :: STORAGE_NAMES(0:2) = &
                                  [character(len=16) :: 'double', 'single', 'single_unshifted']

  integer, parameter :: NSTATE = 10 !! values of one particle's state
  integer, parameter :: NINT = 9    !! entries of /state_int

  !> The state of a run between two steps, besides the populations.
  type :: checkpoint_t
    integer :: step = 0            !! steps done
    integer :: shift = 0           !! rows the window moved
    integer :: samples = 0         !! samples of the /particles series written so far
    integer :: nx = 0, ny = 0      !! lattice
    integer :: np = 0              !! particles
    real(wp) :: dx = 0.0_wp, dt = 0.0_wp
    real(wp), allocatable :: particles(:, :) !! (NSTATE, n)
    logical :: in_episode = .false.
    real(wp), allocatable :: t_start(:), t_end(:), gap_min(:) !! the episodes so far
    integer :: precision = 0       !! how /f is stored: its index in STORAGE_NAMES
  end type checkpoint_t

contains

  !> '<dir>/<name>_chk_<step, 9 digits>.h5'
  function checkpoint_name(dir, name, step) result(path)
    character(len=*), intent(in) :: dir, name
    integer, intent(in) :: step
    character(len=:), allocatable :: path
    character(len=16) :: digits
    write (digits, '(i9.9)') step
    path = dir//'/'//name//'_chk_'//trim(digits)//'.h5'
  end function checkpoint_name

  !> Write `chk` and the rows 1..nyl, columns 1..nx of f (this rank holds global rows
  !! y0+1..y0+nyl) to `path`, atomically. err is '' on success, else the same message on every
  !! rank; the file at `path` is then untouched.
  subroutine checkpoint_write(path, comm, f, nx, nyl, y0, chk, given, err)
    character(len=*), intent(in) :: path
    type(MPI_Comm), intent(in) :: comm
    type(lattice_t), intent(in) :: f
    integer, intent(in) :: nx, nyl, y0
    type(checkpoint_t), intent(in) :: chk
    character(len=*), intent(in) :: given !! the input as read, for the record
    character(len=:), allocatable, intent(out) :: err
    type(io_file_t) :: pf
    integer :: rank, k, ne
    integer, allocatable :: codes(:)
    logical :: bad
    real(wp), allocatable :: buf(:, :, :)
    character(len=:), allocatable :: tmp

    call MPI_Comm_rank(comm, rank)
    tmp = path//'.tmp'
    call io_file_open(pf, tmp, comm, .true., err)
    if (len(err) > 0) then
      err = err//'; is output.dir still there and writable, and is the disk not full?'
      return
    end if
    allocate (buf(nx, nyl, 0:8))
    if (f%single) then
      buf = real(f%s(1:nx, 1:nyl, 0:8), wp)
    else
      buf = f%d(1:nx, 1:nyl, 0:8)
    end if
    call io_put_real(pf, 'f', [integer(hsize_t) :: chk%nx, chk%ny, 9], &
                     [integer(hsize_t) :: 0, y0, 0], [integer(hsize_t) :: nx, nyl, 9], buf, .true.)
    call io_put_real(pf, 'state_real', [integer(hsize_t) :: 2], [integer(hsize_t) :: 0], &
                     [integer(hsize_t) :: 2], [chk%dx, chk%dt], rank == 0)
    ne = size(chk%t_start)
    call io_put_int(pf, 'state_int', [chk%step, chk%shift, chk%samples, chk%nx, chk%ny, &
                                      size(chk%particles, 2), ne, merge(1, 0, chk%in_episode), &
                                      len(given)])
    if (size(chk%particles) > 0) &
      call io_put_real(pf, 'particles', shape(chk%particles, kind=hsize_t), &
                       [integer(hsize_t) :: 0, 0], shape(chk%particles, kind=hsize_t), &
                       chk%particles, rank == 0)
    if (ne > 0) &
      call io_put_real(pf, 'episodes', [integer(hsize_t) :: ne, 3], [integer(hsize_t) :: 0, 0], &
                       [integer(hsize_t) :: ne, 3], &
                       reshape([chk%t_start, chk%t_end, chk%gap_min], [ne, 3]), rank == 0)
    ! the input as character codes (rank 0's)
    allocate (codes(max(1, len(given))))
    codes = 32
    do k = 1, len(given)
      codes(k) = ichar(given(k:k))
    end do
    call io_put_int(pf, 'given', codes)
    call io_put_int(pf, 'precision', [storage_code(f)])
    call io_file_close(pf, err)
    if (len(err) > 0) then
      err = 'writing checkpoint file '''//tmp//''' failed ('//err//'); is the disk full?'
      return
    end if
    ! the complete file takes the final name; the previous checkpoint is left as it was
    bad = .false.
    if (rank == 0) bad = .not. rename_file(tmp, path)
    call MPI_Bcast(bad, 1, MPI_LOGICAL, 0, comm)
    if (bad) err = 'cannot rename '''//tmp//''' to '''//path//''''
  end subroutine checkpoint_write

  !> Read the checkpoint at `path`: its state into `chk` and, when its lattice is nx x ny, it
  !! holds np particles and its populations are stored as f stores them, its particles and the
  !! rows y0+1..y0+nyl of its populations into rows 1..nyl, columns 1..nx of f (the caller
  !! refuses a checkpoint of another lattice, particle count or storage, from chk%nx, ny, np,
  !! precision). Every size and count is checked against the datasets' shapes
  !! and sane bounds before it is used. err is '' on success, else the same message on every
  !! rank.
  subroutine checkpoint_read(path, comm, f, nx, ny, nyl, y0, np, chk, err)
    character(len=*), intent(in) :: path
    type(MPI_Comm), intent(in) :: comm
    type(lattice_t), intent(inout) :: f
    integer, intent(in) :: nx, ny, nyl, y0 !! this run's lattice and slab
    integer, intent(in) :: np              !! this run's particles
    type(checkpoint_t), intent(out) :: chk
    character(len=:), allocatable, intent(out) :: err
    type(io_file_t) :: pf
    integer :: ints(NINT), ne, nd, code(1)
    integer(hsize_t) :: dims(3)
    logical :: exists, any_bad, foreign
    real(wp) :: rr(2)
    real(wp), allocatable :: buf(:, :, :), ep(:, :)
    character(len=:), allocatable :: what, close_err
    character(len=160) :: msg

    err = ''
    inquire (file=path, exist=exists)
    call MPI_Allreduce(.not. exists, any_bad, 1, MPI_LOGICAL, MPI_LOR, comm)
    if (any_bad) then
      err = 'restart file '''//path//''' not found'
      return
    end if
    call io_file_open(pf, path, comm, .false., err)
    if (len(err) > 0) then
      err = 'restart file '''//path//''' is not a dktlbm checkpoint (not HDF5, or damaged)'
      return
    end if

    ! the header: its shape first, then its values, each against what the others say
    what = ''
    ints = 0
    rr = 0.0_wp
    call io_dataset_dims(pf, 'state_int', nd, dims)
    foreign = nd == -1
    if (nd /= 1 .or. dims(1) /= NINT) then
      what = 'no /state_int of 9 entries'
    else
      call io_get_int(pf, 'state_int', ints)
      call io_dataset_dims(pf, 'state_real', nd, dims)
      if (nd /= 1 .or. dims(1) /= 2) then
        what = 'no /state_real of 2 entries'
      else
        call io_get_real(pf, 'state_real', [0_hsize_t], [2_hsize_t], rr)
      end if
    end if
    if (len(what) == 0 .and. len(pf%failed) > 0) what = 'its header cannot be read'
    chk%step = ints(1)
    chk%shift = ints(2)
    chk%samples = ints(3)
    chk%nx = ints(4)
    chk%ny = ints(5)
    chk%np = ints(6)
    ne = ints(7)
    chk%in_episode = ints(8) == 1
    chk%dx = rr(1)
    chk%dt = rr(2)
    if (len(what) == 0) what = header_problem()
    ! the storage of /f; a checkpoint without /precision was written in 8 bytes
    chk%precision = 0
    if (len(what) == 0) then
      call io_dataset_dims(pf, 'precision', nd, dims)
      if (nd == 1 .and. dims(1) == 1) then
        call io_get_int(pf, 'precision', code)
        chk%precision = code(1)
        if (chk%precision < lbound(STORAGE_NAMES, 1) .or. &
            chk%precision > ubound(STORAGE_NAMES, 1)) what = 'a /precision of '//itoa(code(1))// &
                                                         ' (0, 1 or 2)'
      else if (nd /= -1) then
        what = 'a /precision that is not one integer'
      end if
    end if
    ! the populations and particles only when they are this run's; the caller says why not
    if (len(what) == 0 .and. chk%nx == nx .and. chk%ny == ny .and. chk%np == np .and. &
        chk%precision == storage_code(f)) then
      allocate (chk%particles(NSTATE, np), ep(ne, 3))
      if (np > 0) call io_get_real(pf, 'particles', [integer(hsize_t) :: 0, 0], &
                                   [integer(hsize_t) :: NSTATE, np], chk%particles)
      if (ne > 0) call io_get_real(pf, 'episodes', [integer(hsize_t) :: 0, 0], &
                                   [integer(hsize_t) :: ne, 3], ep)
      chk%t_start = ep(:, 1)
      chk%t_end = ep(:, 2)
      chk%gap_min = ep(:, 3)
      allocate (buf(nx, nyl, 0:8))
      call io_get_real(pf, 'f', [integer(hsize_t) :: 0, y0, 0], &
                       [integer(hsize_t) :: nx, nyl, 9], buf)
      if (f%single) then
        ! the values were 4-byte ones: the conversion back is exact
        f%s(1:nx, 1:nyl, 0:8) = real(buf, sp)
      else
        f%d(1:nx, 1:nyl, 0:8) = buf
      end if
      if (len(pf%failed) == 0) then
        if (.not. all(ieee_is_finite(chk%particles)) .or. .not. all(ieee_is_finite(ep))) &
          what = 'non-finite particle or episode values'
      end if
    else
      allocate (chk%particles(NSTATE, 0), chk%t_start(0), chk%t_end(0), chk%gap_min(0))
    end if
    call io_file_close(pf, close_err)
    ! a problem seen on any rank is everyone's (the slabs read different rows)
    call MPI_Allreduce(len(what) > 0, any_bad, 1, MPI_LOGICAL, MPI_LOR, comm)
    if (any_bad .and. len(what) == 0) what = 'a damaged dataset on another rank'
    if (foreign) then
      err = 'restart file '''//path//''' is not a dktlbm checkpoint (no /state_int)'
    else if (len(what) > 0) then
      err = 'restart file '''//path//''' is damaged: '//what//'; use an earlier checkpoint'
    else if (len(close_err) > 0) then
      err = 'restart file '''//path//''' is damaged: '//close_err//'; use an earlier checkpoint'
    end if
  contains
    !> What is wrong with the header, '' if nothing: the counts against sane bounds and the
    !! datasets' shapes (so nothing is allocated from a wrong count).
    function header_problem() result(p)
      character(len=:), allocatable :: p
      p = ''
      if (chk%step < 0 .or. chk%samples < 0 .or. chk%samples > chk%step + 1) then
        write (msg, '(a,i0,a,i0,a)') 'step ', chk%step, ' and samples ', chk%samples, &
          ' (0 <= samples <= step + 1)'
        p = trim(msg)
      else if (chk%nx < 1 .or. chk%ny < 1) then
        write (msg, '(a,i0,a,i0)') 'a lattice of ', chk%nx, ' x ', chk%ny
        p = trim(msg)
      else if (chk%np < 0 .or. chk%np > MAX_PARTICLES) then
        write (msg, '(a,i0,a,i0,a)') 'a particle count of ', chk%np, ' (0 to ', MAX_PARTICLES, ')'
        p = trim(msg)
      else if (ne < 0 .or. ne > chk%step + 1) then
        write (msg, '(a,i0,a)') 'an episode count of ', ne, ' (0 to step + 1)'
        p = trim(msg)
      else if (ints(8) /= 0 .and. ints(8) /= 1) then
        p = 'an in-episode flag other than 0 or 1'
      else if (ints(9) < 0) then
        p = 'a negative length of /given'
      else if (.not. (ieee_is_finite(chk%dx) .and. ieee_is_finite(chk%dt) .and. &
                      chk%dx > 0.0_wp .and. chk%dt > 0.0_wp)) then
        p = 'a lattice spacing or time step that is not a positive number'
      end if
      if (len(p) > 0) return
      call io_dataset_dims(pf, 'f', nd, dims)
      if (nd /= 3 .or. any(dims /= [integer(hsize_t) :: chk%nx, chk%ny, 9])) then
        p = '/f does not hold the '//itoa(chk%nx)//' x '//itoa(chk%ny)//' x 9 populations '// &
            'of its header'
        return
      end if
      call io_dataset_dims(pf, 'particles', nd, dims)
      if (chk%np > 0 .and. (nd /= 2 .or. dims(1) /= NSTATE .or. dims(2) /= chk%np)) then
        p = '/particles does not hold the '//itoa(chk%np)//' particles of its header'
        return
      end if
      call io_dataset_dims(pf, 'episodes', nd, dims)
      if (ne > 0 .and. (nd /= 2 .or. dims(1) /= ne .or. dims(2) /= 3)) then
        p = '/episodes does not hold the '//itoa(ne)//' episodes of its header'
        return
      end if
      if (len(pf%failed) > 0) p = 'its datasets cannot be read'
    end function header_problem

  end subroutine checkpoint_read

  !> The /precision code of the storage of f.
  integer function storage_code(f) result(code)
    type(lattice_t), intent(in) :: f
    do code = lbound(STORAGE_NAMES, 1), ubound(STORAGE_NAMES, 1)
      if (STORAGE_NAMES(code) == lattice_precision_name(f)) return
    end do
    code = 0
  end function storage_code

end module dkt_checkpoint

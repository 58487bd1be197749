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
!> - /run_id: the identity of the run file the run writes (its /run run_id), so that a restart
!>   refuses to continue another run's file; absent in checkpoints of earlier versions;
!> - /precision: how the populations are stored (lbm.precision): 0 'double', 1 'single' (f_i - w_i
!>   in 4 bytes), 2 'single_unshifted', 3 'single_arith' (stored as 1, collided in 4 bytes: a
!>   resume across 1 and 3 is refused, it would not continue bit for bit), 4 'half' (16-bit
!>   codes of f_i - w_i, dkt_half); absent in checkpoints written before single storage existed,
!>   which are 'double'. /f holds the stored values exactly (a 4-byte value converts to 8 bytes
!>   and back without change, and so does a 16-bit code, stored as the integer it is), so a
!>   single-precision or 16-bit run resumes bit for bit too;
!> - /f_checksum (h5py (ny, 2)): a digest of each row of /f, and /state_checksum (2): one of
!>   every other dataset (the values of /state_int, /state_real, /particles, /episodes, /given,
!>   /precision in this order). A digest is two sums modulo the prime 2^32 - 5 over the 32-bit
!>   words of the 8-byte values (Fletcher's checksum), stored as reals (exact below 2^53). A row
!>   is the unit, so any number of ranks writes and checks the same digests. Absent in
!>   checkpoints written before they existed, which are read with a warning.
!>
!> A checkpoint is written to `<file>.tmp` and renamed when complete, so a failed write (disk
!> full, directory gone) never damages the previous checkpoint. A checkpoint is read only after
!> its sizes and counts passed the checks of checkpoint_read (against the datasets' shapes, the
!> scene and sane bounds), so a damaged file is refused before anything is allocated from it.
!> The HDF5 calls are dkt_h5file's.
module dkt_checkpoint
  use iso_fortran_env, only: int64, int16
  use mpi_f08, only: MPI_Comm, MPI_LOGICAL, MPI_LOR, MPI_Allreduce, MPI_Bcast, MPI_Comm_rank, &
                     MPI_INTEGER, MPI_MIN, MPI_CHARACTER, MPI_Barrier
  use hdf5, only: hsize_t
  use ieee_arithmetic, only: ieee_is_finite, ieee_is_nan, ieee_is_negative
  use dkt_kinds, only: wp, sp
  use dkt_store, only: lattice_t, lattice_precision_name
  use iso_c_binding, only: c_long
  use dkt_filesystem, only: rename_file, reserve_space, remove_file
  use dkt_text, only: itoa
  ! the most particles a scene may hold: a count above it in a checkpoint is a damaged file
  use dkt_kinds, only: MAX_PARTICLES
  use dkt_h5file, only: io_file_t, io_file_open, io_file_close, io_put_real, &
                        io_put_int, io_get_real, io_get_int, io_dataset_dims
  implicit none
  private
  public :: checkpoint_t, checkpoint_write, checkpoint_read, checkpoint_rows, checkpoint_name, &
            NSTATE, &
            STORAGE_NAMES

  !> lbm.precision by its code in /precision (0 to 4). 'single_arith' stores what 'single'
  !! stores but has its own code: its checkpoints continue bit for bit only with the 4-byte
  !! collision, so a resume with the other one is refused like any other change of precision.
  character(len=16), parameter :: STORAGE_NAMES(0:4) = &
                                  [character(len=16) :: 'double', 'single', 'single_unshifted', &
                                                         'single_arith', 'half']

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
    logical :: checksums = .false. !! its values were checked against stored digests
    !> the input of the run that wrote it (/given), read back; '' when the file has none
    character(len=:), allocatable :: given
    !> the identity of the run file the run wrote (/run_id; 0 in a file of an earlier version)
    real(wp) :: run_id = 0.0_wp
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
    character(len=:), allocatable :: tmp, reason

    call MPI_Comm_rank(comm, rank)
    tmp = path//'.tmp'
    ! The space first: parallel HDF5 does not come back from a write that failed on some ranks
    ! only (their closes wait on each other for ever), so a full disk is found before any
    ! HDF5 call, by reserving the file's size. The reservation is released when HDF5 creates
    ! the file, with the space it then fills.
    reason = ''
    if (rank == 0) call reserve_space(tmp, checkpoint_bytes(chk, len(given)), reason)
    call agree(reason, comm)
    if (len(reason) > 0) then
      err = 'cannot write checkpoint file '''//path//''': '//reason//' (it needs '// &
            itoa(int(checkpoint_bytes(chk, len(given))/1024_c_long))//' KiB in output.dir)'
      return
    end if
    call io_file_open(pf, tmp, comm, .true., err)
    if (len(err) > 0) then
      call discard(tmp, comm)
      err = 'cannot write checkpoint file '''//path//''': '//err// &
            '; is output.dir still there and writable, and is the disk not full?'
      return
    end if
    allocate (buf(nx, nyl, 0:8))
    if (f%half) then
      buf = real(f%h(1:nx, 1:nyl, 0:8), wp)
    else if (f%single) then
      buf = real(f%s(1:nx, 1:nyl, 0:8), wp)
    else
      buf = f%d(1:nx, 1:nyl, 0:8)
    end if
    call io_put_real(pf, 'f', [integer(hsize_t) :: chk%nx, chk%ny, 9], &
                     [integer(hsize_t) :: 0, y0, 0], [integer(hsize_t) :: nx, nyl, 9], buf, .true.)
    call io_put_real(pf, 'state_real', [integer(hsize_t) :: 2], [integer(hsize_t) :: 0], &
                     [integer(hsize_t) :: 2], [chk%dx, chk%dt], rank == 0)
    call io_put_real(pf, 'run_id', [integer(hsize_t) :: 1], [integer(hsize_t) :: 0], &
                     [integer(hsize_t) :: 1], [chk%run_id], rank == 0)
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
    call io_put_real(pf, 'f_checksum', [integer(hsize_t) :: 2, chk%ny], &
                     [integer(hsize_t) :: 0, y0], [integer(hsize_t) :: 2, nyl], &
                     row_digests(buf), .true.)
    call io_put_real(pf, 'state_checksum', [integer(hsize_t) :: 2], [integer(hsize_t) :: 0], &
                     [integer(hsize_t) :: 2], &
                     state_digest([chk%step, chk%shift, chk%samples, chk%nx, chk%ny, &
                                   size(chk%particles, 2), ne, merge(1, 0, chk%in_episode), &
                                   len(given)], [chk%dx, chk%dt], chk%particles, &
                                  reshape([chk%t_start, chk%t_end, chk%gap_min], [ne, 3]), codes, &
                                  storage_code(f)), rank == 0)
    call io_file_close(pf, err)
    if (len(err) > 0) then
      ! the partial file would fill the disk the run file still needs to close
      call discard(tmp, comm)
      err = 'writing checkpoint file '''//path//''' failed ('//err//'); is the disk full?'
      return
    end if
    ! the complete file takes the final name; the previous checkpoint is left as it was
    bad = .false.
    if (rank == 0) bad = .not. rename_file(tmp, path)
    call MPI_Bcast(bad, 1, MPI_LOGICAL, 0, comm)
    if (bad) err = 'cannot rename '''//tmp//''' to '''//path//''''
  end subroutine checkpoint_write

  !> The size of the checkpoint file of `chk` (bytes), from above: its datasets and 64 KiB
  !! for HDF5's own records.
  function checkpoint_bytes(chk, ngiven) result(bytes)
    type(checkpoint_t), intent(in) :: chk
    integer, intent(in) :: ngiven !! characters of the input
    integer(c_long) :: bytes
    bytes = 8_c_long*chk%nx*chk%ny*9 + 16_c_long*chk%ny + 8_c_long*size(chk%particles) + &
            24_c_long*size(chk%t_start) + 4_c_long*(ngiven + NINT + 1) + 65536_c_long
  end function checkpoint_bytes

  !> Remove the unfinished file `tmp` (rank 0, once every rank is past it).
  subroutine discard(tmp, comm)
    character(len=*), intent(in) :: tmp
    type(MPI_Comm), intent(in) :: comm
    integer :: rank
    call MPI_Barrier(comm)
    call MPI_Comm_rank(comm, rank)
    if (rank == 0) call remove_file(tmp)
    call MPI_Barrier(comm)
  end subroutine discard

  !> Read the checkpoint at `path`: its state into `chk` and, when its lattice is nx x ny, it
  !! holds np particles and its populations are stored as f stores them, the rows y0+1..y0+nyl
  !! of its populations into rows 1..nyl, columns 1..nx of f (the caller refuses a checkpoint of
  !! another lattice, particle count or storage, from chk%nx, ny, np, precision). Every size
  !! and count is checked against the datasets' shapes and sane bounds before it is used, every
  !! value against its digest (when the file has digests), and the particles, episodes and
  !! populations must be finite. err is '' on success, else the same message on every rank,
  !! naming the file, the dataset and the value.
  subroutine checkpoint_read(path, comm, f, nx, ny, nyl, y0, chk, err)
    character(len=*), intent(in) :: path
    type(MPI_Comm), intent(in) :: comm
    type(lattice_t), intent(inout) :: f
    integer, intent(in) :: nx, ny, nyl, y0 !! this run's lattice and slab
    type(checkpoint_t), intent(out) :: chk
    character(len=:), allocatable, intent(out) :: err
    type(io_file_t) :: pf
    integer :: ints(NINT)
    logical :: foreign
    real(wp) :: rr(2)
    character(len=:), allocatable :: what, close_err

    call open_checkpoint(path, comm, pf, err)
    if (len(err) > 0) return
    call read_header(pf, chk, ints, rr, foreign, what)
    if (len(what) == 0) call read_precision(pf, chk, what)
    ! the digests: both or none (a checkpoint written before they existed)
    if (len(what) == 0) what = checksum_shapes(pf, chk, ints(9))
    if (len(what) == 0) then
      call read_state(pf, chk, ints, rr, what)
    else
      allocate (chk%particles(NSTATE, 0), chk%t_start(0), chk%t_end(0), chk%gap_min(0))
      chk%given = ''
    end if
    ! the populations only when they are this run's; the caller says why not
    if (len(what) == 0 .and. chk%nx == nx .and. chk%ny == ny .and. &
        chk%precision == storage_code(f)) &
      call read_populations(pf, f, nx, nyl, y0, chk%checksums, what)
    if (len(what) == 0 .and. len(pf%failed) > 0) what = 'its datasets cannot be read'
    call io_file_close(pf, close_err)
    ! a problem seen on any rank is everyone's (the slabs read different rows): the message
    ! of the lowest rank that saw one
    call agree(what, comm)
    if (foreign) then
      err = 'restart file '''//path//''' is not a dktlbm checkpoint (no /state_int)'
    else if (len(what) > 0) then
      err = 'restart file '''//path//''' is damaged: '//what//'; use an earlier checkpoint'
    else if (len(close_err) > 0) then
      err = 'restart file '''//path//''' is damaged: '//close_err//'; use an earlier checkpoint'
    end if
  end subroutine checkpoint_read

  !> The rows of the lattice the checkpoint at `path` holds (its /state_int), every rank; 0 when
  !! it cannot be read (checkpoint_read then says why). A run resumes on the lattice of its
  !! checkpoint, which a window may have grown (docs/model.md §5).
  integer function checkpoint_rows(path, comm) result(ny)
    character(len=*), intent(in) :: path
    type(MPI_Comm), intent(in) :: comm
    type(io_file_t) :: pf
    type(checkpoint_t) :: chk
    integer :: ints(NINT)
    real(wp) :: rr(2)
    logical :: foreign
    character(len=:), allocatable :: err, what
    ny = 0
    call open_checkpoint(path, comm, pf, err)
    if (len(err) > 0) return
    call read_header(pf, chk, ints, rr, foreign, what)
    call io_file_close(pf, err)
    if (.not. foreign .and. len(what) == 0 .and. len(err) == 0) ny = chk%ny
  end function checkpoint_rows

  !> Open the checkpoint at `path` for reading on every rank of `comm`; err is '' on success,
  !! else the same message on every rank (the file is missing or not HDF5).
  subroutine open_checkpoint(path, comm, pf, err)
    character(len=*), intent(in) :: path
    type(MPI_Comm), intent(in) :: comm
    type(io_file_t), intent(inout) :: pf
    character(len=:), allocatable, intent(out) :: err
    logical :: exists, any_bad

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
  end subroutine open_checkpoint

  !> The header: /state_int into `ints` and /state_real into `rr`, their shapes first, then
  !! their values (into chk), each against what the others say. `foreign` when the file has
  !! no /state_int at all; `what` is what is wrong, '' if nothing.
  subroutine read_header(pf, chk, ints, rr, foreign, what)
    type(io_file_t), intent(inout) :: pf
    type(checkpoint_t), intent(inout) :: chk
    integer, intent(out) :: ints(NINT)
    real(wp), intent(out) :: rr(2)
    logical, intent(out) :: foreign
    character(len=:), allocatable, intent(out) :: what
    integer :: nd
    integer(hsize_t) :: dims(3)

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
    chk%in_episode = ints(8) == 1
    chk%dx = rr(1)
    chk%dt = rr(2)
    if (len(what) == 0) what = header_problem(pf, chk, ints)
  end subroutine read_header

  !> What is wrong with the header, '' if nothing: the counts against sane bounds and the
  !! datasets' shapes (so nothing is allocated from a wrong count).
  function header_problem(pf, chk, ints) result(p)
    type(io_file_t), intent(inout) :: pf
    type(checkpoint_t), intent(in) :: chk
    integer, intent(in) :: ints(NINT)
    character(len=:), allocatable :: p
    integer(int64) :: last
    integer :: ne, nd
    integer(hsize_t) :: dims(3)
    character(len=160) :: msg

    ne = ints(7)
    ! step + 1, which a step of huge(0) must not overflow
    last = int(chk%step, int64) + 1
    p = ''
    if (chk%step < 0 .or. chk%samples < 0 .or. chk%samples > last) then
      write (msg, '(a,i0,a,i0,a)') '/state_int holds step ', chk%step, ' and samples ', &
        chk%samples, ' (0 <= samples <= step + 1)'
      p = trim(msg)
    else if (chk%shift < 0 .or. chk%shift > last) then
      ! the window moves down only, and less than a row a step (run.particle_speed_limit <= 1)
      write (msg, '(a,i0,a,i0,a)') '/state_int holds a window shift of ', chk%shift, &
        ' rows at step ', chk%step, ' (0 to step + 1)'
      p = trim(msg)
    else if (chk%nx < 1 .or. chk%ny < 1) then
      write (msg, '(a,i0,a,i0)') 'a lattice of ', chk%nx, ' x ', chk%ny
      p = trim(msg)
    else if (chk%np < 0 .or. chk%np > MAX_PARTICLES) then
      write (msg, '(a,i0,a,i0,a)') 'a particle count of ', chk%np, ' (0 to ', MAX_PARTICLES, ')'
      p = trim(msg)
    else if (ne < 0 .or. ne > last) then
      write (msg, '(a,i0,a)') 'an episode count of ', ne, ' (0 to step + 1)'
      p = trim(msg)
    else if (ints(8) /= 0 .and. ints(8) /= 1) then
      p = 'an in-episode flag other than 0 or 1'
    else if (ints(9) < 0) then
      p = 'a negative length of /given'
    else if (.not. (ieee_is_finite(chk%dx) .and. ieee_is_finite(chk%dt))) then
      p = 'a lattice spacing or time step that is not a positive number'
    else if (.not. (chk%dx > 0.0_wp .and. chk%dt > 0.0_wp)) then
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

  !> The storage of /f into chk%precision; a checkpoint without /precision was written in 8
  !! bytes. `what` is what is wrong, '' if nothing.
  subroutine read_precision(pf, chk, what)
    type(io_file_t), intent(inout) :: pf
    type(checkpoint_t), intent(inout) :: chk
    character(len=:), allocatable, intent(inout) :: what
    integer :: nd, code(1)
    integer(hsize_t) :: dims(3)

    chk%precision = 0
    code = 0
    call io_dataset_dims(pf, 'precision', nd, dims)
    if (nd == 1 .and. dims(1) == 1) then
      call io_get_int(pf, 'precision', code)
      chk%precision = code(1)
      if (chk%precision < lbound(STORAGE_NAMES, 1) .or. &
          chk%precision > ubound(STORAGE_NAMES, 1)) what = 'a /precision of '//itoa(code(1))// &
                                                       ' (0 to 4)'
    else if (nd /= -1) then
      what = 'a /precision that is not one integer'
    end if
  end subroutine read_precision

  !> Whether the file has digests (chk%checksums), and what is wrong with their shapes;
  !! `ngiven` is the length of /given its header gives.
  function checksum_shapes(pf, chk, ngiven) result(p)
    type(io_file_t), intent(inout) :: pf
    type(checkpoint_t), intent(inout) :: chk
    integer, intent(in) :: ngiven
    character(len=:), allocatable :: p
    integer :: nd_f, nd_s, nd_g
    integer(hsize_t) :: dims_f(3), dims_s(3), dims_g(3)
    p = ''
    call io_dataset_dims(pf, 'f_checksum', nd_f, dims_f)
    call io_dataset_dims(pf, 'state_checksum', nd_s, dims_s)
    call io_dataset_dims(pf, 'given', nd_g, dims_g)
    chk%checksums = nd_f /= -1 .or. nd_s /= -1
    if (.not. chk%checksums) return
    if (nd_f /= 2 .or. dims_f(1) /= 2 .or. dims_f(2) /= chk%ny) then
      p = 'no /f_checksum of 2 x '//itoa(chk%ny)//' digests'
    else if (nd_s /= 1 .or. dims_s(1) /= 2) then
      p = 'no /state_checksum of 2 digests'
    else if (nd_g /= 1 .or. dims_g(1) /= max(1, ngiven)) then
      p = '/given does not hold the '//itoa(ngiven)//' characters of its header'
    end if
  end function checksum_shapes

  !> The small datasets, whose counts the header gave and their shapes confirmed: the
  !! particles and episodes into chk, checked against /state_checksum (when the file has
  !! digests) and for values that are not finite. `what` is what is wrong, '' if nothing.
  subroutine read_state(pf, chk, ints, rr, what)
    type(io_file_t), intent(inout) :: pf
    type(checkpoint_t), intent(inout) :: chk
    integer, intent(in) :: ints(NINT)
    real(wp), intent(in) :: rr(2)
    character(len=:), allocatable, intent(inout) :: what
    real(wp), allocatable :: ep(:, :)
    integer, allocatable :: codes(:)
    real(wp) :: sums(2)
    integer :: ne, nd
    integer(hsize_t) :: dims(3)
    logical :: has_given
    real(wp) :: id(1)

    ne = ints(7)
    allocate (chk%particles(NSTATE, chk%np), ep(ne, 3), codes(max(1, ints(9))))
    if (chk%np > 0) call io_get_real(pf, 'particles', [integer(hsize_t) :: 0, 0], &
                                     [integer(hsize_t) :: NSTATE, chk%np], chk%particles)
    if (ne > 0) call io_get_real(pf, 'episodes', [integer(hsize_t) :: 0, 0], &
                                 [integer(hsize_t) :: ne, 3], ep)
    call io_dataset_dims(pf, 'run_id', nd, dims)
    if (nd == 1 .and. dims(1) == 1) then
      call io_get_real(pf, 'run_id', [0_hsize_t], [1_hsize_t], id)
      chk%run_id = id(1)
    end if
    codes = 32
    call io_dataset_dims(pf, 'given', nd, dims)
    ! a checkpoint without digests may still hold its input
    has_given = nd == 1 .and. dims(1) == max(1, ints(9))
    if (has_given .and. .not. chk%checksums) call io_get_int(pf, 'given', codes)
    if (chk%checksums) then
      call io_get_int(pf, 'given', codes)
      call io_get_real(pf, 'state_checksum', [0_hsize_t], [2_hsize_t], sums)
      if (len(pf%failed) == 0 .and. &
          any(sums /= state_digest(ints, rr, chk%particles, ep, codes, chk%precision))) &
        what = 'its state (/state_int, /state_real, /particles, /episodes, /given, '// &
               '/precision) does not match /state_checksum'
    end if
    if (len(what) == 0 .and. len(pf%failed) == 0) what = non_finite_state(chk%particles, ep)
    chk%given = ''
    if (has_given .and. len(pf%failed) == 0) chk%given = given_text(codes(:ints(9)))
    chk%t_start = ep(:, 1)
    chk%t_end = ep(:, 2)
    chk%gap_min = ep(:, 3)
  end subroutine read_state

  !> The rows y0+1..y0+nyl of /f into rows 1..nyl, columns 1..nx of f, checked against
  !! /f_checksum (when the file has digests, `checksums`) and for values that are not finite;
  !! refused (`what` set), f keeps what it held.
  subroutine read_populations(pf, f, nx, nyl, y0, checksums, what)
    type(io_file_t), intent(inout) :: pf
    type(lattice_t), intent(inout) :: f
    integer, intent(in) :: nx, nyl, y0
    logical, intent(in) :: checksums
    character(len=:), allocatable, intent(inout) :: what
    real(wp), allocatable :: buf(:, :, :), rows(:, :)

    allocate (buf(nx, nyl, 0:8))
    call io_get_real(pf, 'f', [integer(hsize_t) :: 0, y0, 0], &
                     [integer(hsize_t) :: nx, nyl, 9], buf)
    if (checksums .and. len(pf%failed) == 0) then
      allocate (rows(2, nyl))
      call io_get_real(pf, 'f_checksum', [integer(hsize_t) :: 0, y0], &
                       [integer(hsize_t) :: 2, nyl], rows)
      if (len(pf%failed) == 0) what = row_mismatch(rows, row_digests(buf), y0)
    end if
    if (len(what) == 0 .and. len(pf%failed) == 0) what = non_finite_population(buf, y0)
    if (len(what) == 0 .and. f%half) then
      if (any(buf /= aint(buf) .or. buf < -32768.0_wp .or. buf > 32767.0_wp)) &
        what = 'a population that is not a 16-bit code (lbm.precision = ''half'')'
    end if
    if (len(what) > 0) then
      ! refused: f keeps what it held
    else if (f%half) then
      ! the values were 16-bit codes: the conversion back is exact
      f%h(1:nx, 1:nyl, 0:8) = int(buf, int16)
    else if (f%single) then
      ! the values were 4-byte ones: the conversion back is exact
      f%s(1:nx, 1:nyl, 0:8) = real(buf, sp)
    else
      f%d(1:nx, 1:nyl, 0:8) = buf
    end if
  end subroutine read_populations

  !> The first particle or episode value that is not finite, '' if none.
  function non_finite_state(particles, ep) result(p)
    real(wp), intent(in) :: particles(:, :) !! (NSTATE, n)
    real(wp), intent(in) :: ep(:, :)        !! (episodes, 3)
    character(len=:), allocatable :: p
    integer :: at(2)
    p = ''
    if (.not. all(ieee_is_finite(particles))) then
      at = findloc(ieee_is_finite(particles), .false.)
      p = '/particles holds the value '//non_finite_text(particles(at(1), at(2)))// &
          ' for particle '//itoa(at(2))//' (quantity '//itoa(at(1))// &
          ' of x, y, u, v, omega, fx, fy, torque, cx, cy)'
    else if (.not. all(ieee_is_finite(ep))) then
      p = '/episodes holds a value that is not finite'
    end if
  end function non_finite_state

  !> The first population of this rank's rows (below them y0 rows) that is not finite, '' if
  !! none.
  function non_finite_population(b, y0) result(p)
    real(wp), intent(in) :: b(:, :, 0:)
    integer, intent(in) :: y0
    character(len=:), allocatable :: p
    integer :: at(3)
    p = ''
    if (all(ieee_is_finite(b))) return
    at = findloc(ieee_is_finite(b), .false.)
    p = '/f holds the value '//non_finite_text(b(at(1), at(2), at(3) - 1))//' at x = '// &
        itoa(at(1))//', row '//itoa(y0 + at(2))//', population '//itoa(at(3) - 1)
  end function non_finite_population

  !> The first of this rank's rows (below them y0 rows) whose digest differs from the stored
  !! one, '' if none.
  function row_mismatch(stored, computed, y0) result(p)
    real(wp), intent(in) :: stored(:, :), computed(:, :)
    integer, intent(in) :: y0
    character(len=:), allocatable :: p
    integer :: j
    p = ''
    do j = 1, size(stored, 2)
      if (all(stored(:, j) == computed(:, j))) cycle
      p = '/f row '//itoa(y0 + j)//' does not match its digest in /f_checksum (a damaged '// &
          'or altered value)'
      return
    end do
  end function row_mismatch

  !> The text of the character codes of /given (as checkpoint_write made them with ichar); ''
  !! when a code is not one of a byte.
  pure function given_text(codes) result(s)
    integer, intent(in) :: codes(:)
    character(len=:), allocatable :: s
    integer :: k
    if (any(codes < 0 .or. codes > 255)) then
      s = ''
      return
    end if
    allocate (character(len=size(codes)) :: s)
    do k = 1, size(codes)
      s(k:k) = char(codes(k))
    end do
  end function given_text

  !> 'NaN', 'Infinity' or '-Infinity', the text of a value that is not finite (without an ordered
  !! comparison, which traps on NaN in the checked build).
  pure function non_finite_text(x) result(s)
    real(wp), intent(in) :: x
    character(len=:), allocatable :: s
    if (ieee_is_nan(x)) then
      s = 'NaN'
    else if (ieee_is_negative(x)) then
      s = '-Infinity'
    else
      s = 'Infinity'
    end if
  end function non_finite_text

  !> Every rank gets the message `what` of the lowest rank whose `what` is not ''.
  subroutine agree(what, comm)
    character(len=:), allocatable, intent(inout) :: what
    type(MPI_Comm), intent(in) :: comm
    integer :: rank, owner, n
    call MPI_Comm_rank(comm, rank)
    call MPI_Allreduce(merge(rank, huge(0), len(what) > 0), owner, 1, MPI_INTEGER, MPI_MIN, &
                       comm)
    if (owner == huge(0)) return
    n = len(what)
    call MPI_Bcast(n, 1, MPI_INTEGER, owner, comm)
    if (rank /= owner) then
      deallocate (what)
      allocate (character(len=n) :: what)
    end if
    call MPI_Bcast(what, n, MPI_CHARACTER, owner, comm)
  end subroutine agree

  !> The digests of the rows of b (x, row, population): row j's 9 nx values in the order
  !! (x, population), as two sums each.
  function row_digests(b) result(d)
    real(wp), intent(in) :: b(:, :, 0:)
    real(wp) :: d(2, size(b, 2))
    integer :: j
    do j = 1, size(b, 2)
      d(:, j) = digest(reshape(b(:, j, :), [size(b, 1)*size(b, 3)]))
    end do
  end function row_digests

  !> The digest of the state datasets as checkpoint_write stores them: the integers and the
  !! character codes as reals (exact), then the reals.
  function state_digest(ints, rr, particles, ep, codes, precision) result(d)
    integer, intent(in) :: ints(:), codes(:), precision
    real(wp), intent(in) :: rr(:), particles(:, :), ep(:, :)
    real(wp) :: d(2)
    d = digest([real(ints, wp), rr, reshape(particles, [size(particles)]), &
                reshape(ep, [size(ep)]), real(codes, wp), real(precision, wp)])
  end function state_digest

  !> Fletcher's checksum of the 32-bit words of v: two sums modulo the prime 2^32 - 5, the
  !! second of the running first, so that a changed, swapped or moved word changes the
  !! digest. As reals: both are below 2^32, exact in 8 bytes.
  pure function digest(v) result(d)
    real(wp), intent(in) :: v(:)
    real(wp) :: d(2)
    integer(int64), parameter :: P = 4294967291_int64, LOW = 4294967295_int64
    integer(int64) :: a, b, w
    integer :: k
    a = 1
    b = 0
    do k = 1, size(v)
      w = transfer(v(k), w)
      a = mod(a + iand(w, LOW), P)
      b = mod(b + a, P)
      a = mod(a + shiftr(w, 32), P)
      b = mod(b + a, P)
    end do
    d = real([a, b], wp)
  end function digest

  !> The /precision code of the storage of f.
  integer function storage_code(f) result(code)
    type(lattice_t), intent(in) :: f
    do code = lbound(STORAGE_NAMES, 1), ubound(STORAGE_NAMES, 1)
      if (STORAGE_NAMES(code) == lattice_precision_name(f)) return
    end do
    code = 0
  end function storage_code

end module dkt_checkpoint

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
!> - /given: the input as read, as character codes, for the record.
!>
!> A checkpoint is written to `<file>.tmp` and renamed when complete, so a failed write (disk
!> full, directory gone) never damages the previous checkpoint.
module dkt_checkpoint
  use mpi_f08, only: MPI_Comm, MPI_INFO_NULL, MPI_LOGICAL, MPI_LOR, MPI_Allreduce, MPI_Bcast, &
                     MPI_Comm_rank
  use dkt_kinds, only: wp
  use dkt_filesystem, only: rename_file
  use hdf5, only: hid_t, hsize_t, h5open_f, h5kind_to_type, H5_REAL_KIND, H5_INTEGER_KIND, &
                  h5fcreate_f, h5fopen_f, h5fclose_f, H5F_ACC_TRUNC_F, H5F_ACC_RDONLY_F, &
                  h5pcreate_f, h5pclose_f, H5P_FILE_ACCESS_F, H5P_DATASET_XFER_F, &
                  h5pset_fapl_mpio_f, h5pset_dxpl_mpio_f, H5FD_MPIO_COLLECTIVE_F, &
                  h5eset_auto_f, h5screate_simple_f, h5sclose_f, h5sselect_hyperslab_f, &
                  h5sselect_none_f, H5S_SELECT_SET_F, h5dcreate_f, h5dopen_f, h5dclose_f, &
                  h5dwrite_f, h5dread_f, h5dget_space_f, h5sget_simple_extent_dims_f, &
                  h5lexists_f
  implicit none
  private
  public :: checkpoint_t, checkpoint_write, checkpoint_read, checkpoint_name, NSTATE

  integer, parameter :: NSTATE = 10 !! values of one particle's state

  !> The state of a run between two steps, besides the populations.
  type :: checkpoint_t
    integer :: step = 0            !! steps done
    integer :: shift = 0           !! rows the window moved
    integer :: samples = 0         !! samples of the /particles series written so far
    integer :: nx = 0, ny = 0      !! lattice
    real(wp) :: dx = 0.0_wp, dt = 0.0_wp
    real(wp), allocatable :: particles(:, :) !! (NSTATE, n)
    logical :: in_episode = .false.
    real(wp), allocatable :: t_start(:), t_end(:), gap_min(:) !! the episodes so far
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
    real(wp), intent(in) :: f(0:, 0:, 0:)
    integer, intent(in) :: nx, nyl, y0
    type(checkpoint_t), intent(in) :: chk
    character(len=*), intent(in) :: given !! the input as read, for the record
    character(len=:), allocatable, intent(out) :: err
    integer(hid_t) :: file, fapl, dxpl, rtype
    integer :: hdferr, rank, e
    logical :: bad, any_bad
    real(wp), allocatable :: buf(:, :, :)
    character(len=:), allocatable :: tmp

    err = ''
    call MPI_Comm_rank(comm, rank)
    tmp = path//'.tmp'
    call h5open_f(hdferr)
    rtype = h5kind_to_type(wp, H5_REAL_KIND)
    call h5pcreate_f(H5P_FILE_ACCESS_F, fapl, hdferr)
    call h5pset_fapl_mpio_f(fapl, comm%MPI_VAL, MPI_INFO_NULL%MPI_VAL, hdferr)
    call h5eset_auto_f(0, hdferr)
    call h5fcreate_f(tmp, H5F_ACC_TRUNC_F, file, e, access_prp=fapl)
    call h5eset_auto_f(1, hdferr)
    call h5pclose_f(fapl, hdferr)
    bad = e < 0
    call MPI_Allreduce(bad, any_bad, 1, MPI_LOGICAL, MPI_LOR, comm)
    if (any_bad) then
      err = 'cannot create checkpoint file '''//tmp//'''; is output.dir still there and '// &
            'writable, and is the disk not full?'
      return
    end if
    call h5pcreate_f(H5P_DATASET_XFER_F, dxpl, hdferr)
    call h5pset_dxpl_mpio_f(dxpl, H5FD_MPIO_COLLECTIVE_F, hdferr)

    bad = .false.
    allocate (buf(nx, nyl, 0:8))
    buf = f(1:nx, 1:nyl, 0:8)
    call write_real(file, 'f', [integer(hsize_t) :: chk%nx, chk%ny, 9], &
                    [integer(hsize_t) :: 0, y0, 0], [integer(hsize_t) :: nx, nyl, 9], buf, .true.)
    call write_real(file, 'state_real', [integer(hsize_t) :: 2], [integer(hsize_t) :: 0], &
                    [integer(hsize_t) :: 2], [chk%dx, chk%dt], rank == 0)
    call write_int(file, 'state_int', [chk%step, chk%shift, chk%samples, chk%nx, chk%ny, &
                                       size(chk%particles, 2), size(chk%t_start), &
                                       merge(1, 0, chk%in_episode), len(given)])
    if (size(chk%particles) > 0) &
      call write_real(file, 'particles', shape(chk%particles, kind=hsize_t), &
                      [integer(hsize_t) :: 0, 0], shape(chk%particles, kind=hsize_t), &
                      chk%particles, rank == 0)
    if (size(chk%t_start) > 0) &
      call write_real(file, 'episodes', [integer(hsize_t) :: size(chk%t_start), 3], &
                      [integer(hsize_t) :: 0, 0], [integer(hsize_t) :: size(chk%t_start), 3], &
                      reshape([chk%t_start, chk%t_end, chk%gap_min], [size(chk%t_start), 3]), &
                      rank == 0)
    call write_text(file, 'given', given)
    call h5pclose_f(dxpl, hdferr)
    call h5fclose_f(file, e)
    bad = bad .or. e < 0
    call MPI_Allreduce(bad, any_bad, 1, MPI_LOGICAL, MPI_LOR, comm)
    if (any_bad) then
      err = 'writing checkpoint file '''//tmp//''' failed; is the disk full?'
      return
    end if
    ! the complete file takes the final name; the previous checkpoint is left as it was
    if (rank == 0) bad = .not. rename_file(tmp, path)
    call MPI_Bcast(bad, 1, MPI_LOGICAL, 0, comm)
    if (bad) err = 'cannot rename '''//tmp//''' to '''//path//''''
  contains
    !> A real dataset of shape dims; this rank writes block (start, count) of it if `mine`.
    subroutine write_real(loc, name, dims, start, count, values, mine)
      integer(hid_t), intent(in) :: loc
      character(len=*), intent(in) :: name
      integer(hsize_t), intent(in) :: dims(:), start(:), count(:)
      real(wp), intent(in) :: values(*)
      logical, intent(in) :: mine
      integer(hid_t) :: space, dset, mspace
      integer :: err1
      call h5screate_simple_f(size(dims), dims, space, err1)
      call h5dcreate_f(loc, name, rtype, space, dset, err1)
      bad = bad .or. err1 < 0
      call h5sclose_f(space, err1)
      call h5dget_space_f(dset, space, err1)
      if (mine .and. product(count) > 0) then
        call h5sselect_hyperslab_f(space, H5S_SELECT_SET_F, start, count, err1)
        call h5screate_simple_f(size(count), count, mspace, err1)
      else
        call h5sselect_none_f(space, err1)
        call h5screate_simple_f(1, [1_hsize_t], mspace, err1)
        call h5sselect_none_f(mspace, err1)
      end if
      call h5dwrite_f(dset, rtype, values(1:max(1_hsize_t, product(count))), count, err1, &
                      mem_space_id=mspace, file_space_id=space, xfer_prp=dxpl)
      bad = bad .or. err1 < 0
      call h5sclose_f(mspace, err1)
      call h5sclose_f(space, err1)
      call h5dclose_f(dset, err1)
    end subroutine write_real

    subroutine write_int(loc, name, values)
      integer(hid_t), intent(in) :: loc
      character(len=*), intent(in) :: name
      integer, intent(in) :: values(:)
      integer(hid_t) :: space, dset, mspace, itype
      integer :: err1
      itype = h5kind_to_type(kind(0), H5_INTEGER_KIND)
      call h5screate_simple_f(1, [size(values, kind=hsize_t)], space, err1)
      call h5dcreate_f(loc, name, itype, space, dset, err1)
      bad = bad .or. err1 < 0
      call h5screate_simple_f(1, [size(values, kind=hsize_t)], mspace, err1)
      if (rank /= 0) then
        call h5sselect_none_f(space, err1)
        call h5sselect_none_f(mspace, err1)
      end if
      call h5dwrite_f(dset, itype, values, [size(values, kind=hsize_t)], err1, &
                      mem_space_id=mspace, file_space_id=space, xfer_prp=dxpl)
      bad = bad .or. err1 < 0
      call h5sclose_f(mspace, err1)
      call h5sclose_f(space, err1)
      call h5dclose_f(dset, err1)
    end subroutine write_int

    !> Text as a 1-D dataset of character codes (rank 0's).
    subroutine write_text(loc, name, text)
      integer(hid_t), intent(in) :: loc
      character(len=*), intent(in) :: name, text
      integer :: codes(max(1, len(text))), k
      codes = 32
      do k = 1, len(text)
        codes(k) = ichar(text(k:k))
      end do
      call write_int(loc, name, codes)
    end subroutine write_text
  end subroutine checkpoint_write

  !> Read the checkpoint at `path`: its state into `chk` and, when its lattice is nx x ny, the
  !! rows y0+1..y0+nyl of its populations into rows 1..nyl, columns 1..nx of f (the caller
  !! refuses a checkpoint of another lattice). err is '' on success, else the same message on
  !! every rank.
  subroutine checkpoint_read(path, comm, f, nx, ny, nyl, y0, chk, err)
    character(len=*), intent(in) :: path
    type(MPI_Comm), intent(in) :: comm
    real(wp), intent(inout) :: f(0:, 0:, 0:)
    integer, intent(in) :: nx, ny, nyl, y0 !! this run's lattice and slab
    type(checkpoint_t), intent(out) :: chk
    character(len=:), allocatable, intent(out) :: err
    integer(hid_t) :: file, fapl, dxpl, rtype, itype
    integer :: hdferr, e, ints(9), np, ne
    logical :: bad, any_bad, exists, found
    real(wp), allocatable :: buf(:, :, :), rr(:), ep(:, :)

    err = ''
    inquire (file=path, exist=exists)
    call MPI_Allreduce(.not. exists, any_bad, 1, MPI_LOGICAL, MPI_LOR, comm)
    if (any_bad) then
      err = 'restart file '''//path//''' not found'
      return
    end if
    call h5open_f(hdferr)
    rtype = h5kind_to_type(wp, H5_REAL_KIND)
    itype = h5kind_to_type(kind(0), H5_INTEGER_KIND)
    call h5pcreate_f(H5P_FILE_ACCESS_F, fapl, hdferr)
    call h5pset_fapl_mpio_f(fapl, comm%MPI_VAL, MPI_INFO_NULL%MPI_VAL, hdferr)
    call h5eset_auto_f(0, hdferr)
    call h5fopen_f(path, H5F_ACC_RDONLY_F, file, e, access_prp=fapl)
    call h5pclose_f(fapl, hdferr)
    bad = e < 0
    if (.not. bad) then
      call h5lexists_f(file, 'state_int', found, e)
      bad = .not. found .or. e < 0
      if (bad) call h5fclose_f(file, e)
    end if
    call h5eset_auto_f(1, hdferr)
    call MPI_Allreduce(bad, any_bad, 1, MPI_LOGICAL, MPI_LOR, comm)
    if (any_bad) then
      err = 'restart file '''//path//''' is not a dktlbm checkpoint (not HDF5, or no /state_int)'
      return
    end if
    call h5pcreate_f(H5P_DATASET_XFER_F, dxpl, hdferr)
    call h5pset_dxpl_mpio_f(dxpl, H5FD_MPIO_COLLECTIVE_F, hdferr)
    bad = .false.

    call read_int(file, 'state_int', ints)
    chk%step = ints(1)
    chk%shift = ints(2)
    chk%samples = ints(3)
    chk%nx = ints(4)
    chk%ny = ints(5)
    np = ints(6)
    ne = ints(7)
    chk%in_episode = ints(8) == 1
    allocate (rr(2))
    call read_real(file, 'state_real', [integer(hsize_t) :: 0], [integer(hsize_t) :: 2], rr)
    chk%dx = rr(1)
    chk%dt = rr(2)
    allocate (chk%particles(NSTATE, np))
    if (np > 0) call read_real(file, 'particles', [integer(hsize_t) :: 0, 0], &
                               [integer(hsize_t) :: NSTATE, np], chk%particles)
    allocate (ep(ne, 3))
    if (ne > 0) call read_real(file, 'episodes', [integer(hsize_t) :: 0, 0], &
                               [integer(hsize_t) :: ne, 3], ep)
    chk%t_start = ep(:, 1)
    chk%t_end = ep(:, 2)
    chk%gap_min = ep(:, 3)
    ! the populations only if the lattice is the one of this run; the caller says why not
    if (chk%nx == nx .and. chk%ny == ny) then
      allocate (buf(nx, nyl, 0:8))
      call read_real(file, 'f', [integer(hsize_t) :: 0, y0, 0], [integer(hsize_t) :: nx, nyl, 9], &
                     buf)
      f(1:nx, 1:nyl, 0:8) = buf
    end if
    call h5pclose_f(dxpl, hdferr)
    call h5fclose_f(file, e)
    call MPI_Allreduce(bad, any_bad, 1, MPI_LOGICAL, MPI_LOR, comm)
    if (any_bad) err = 'reading restart file '''//path//''' failed'
  contains
    subroutine read_real(loc, name, start, count, values)
      integer(hid_t), intent(in) :: loc
      character(len=*), intent(in) :: name
      integer(hsize_t), intent(in) :: start(:), count(:)
      real(wp), intent(out) :: values(*)
      integer(hid_t) :: dset, space, mspace
      integer :: err1
      call h5dopen_f(loc, name, dset, err1)
      bad = bad .or. err1 < 0
      call h5dget_space_f(dset, space, err1)
      call h5sselect_hyperslab_f(space, H5S_SELECT_SET_F, start, count, err1)
      call h5screate_simple_f(size(count), count, mspace, err1)
      call h5dread_f(dset, rtype, values(1:product(count)), count, err1, &
                     mem_space_id=mspace, file_space_id=space, xfer_prp=dxpl)
      bad = bad .or. err1 < 0
      call h5sclose_f(mspace, err1)
      call h5sclose_f(space, err1)
      call h5dclose_f(dset, err1)
    end subroutine read_real

    subroutine read_int(loc, name, values)
      integer(hid_t), intent(in) :: loc
      character(len=*), intent(in) :: name
      integer, intent(out) :: values(:)
      integer(hid_t) :: dset, space, mspace
      integer :: err1
      call h5dopen_f(loc, name, dset, err1)
      bad = bad .or. err1 < 0
      call h5dget_space_f(dset, space, err1)
      call h5sselect_hyperslab_f(space, H5S_SELECT_SET_F, [0_hsize_t], &
                                 [size(values, kind=hsize_t)], err1)
      call h5screate_simple_f(1, [size(values, kind=hsize_t)], mspace, err1)
      call h5dread_f(dset, itype, values, [size(values, kind=hsize_t)], err1, &
                     mem_space_id=mspace, file_space_id=space, xfer_prp=dxpl)
      bad = bad .or. err1 < 0
      call h5sclose_f(mspace, err1)
      call h5sclose_f(space, err1)
      call h5dclose_f(dset, err1)
    end subroutine read_int
  end subroutine checkpoint_read

end module dkt_checkpoint

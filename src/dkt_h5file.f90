!> The parallel-HDF5 file layer under the output: the lifetime of the HDF5 library, shared by
!> every open file of the process (the run file of dkt_io and the checkpoints), and the plain
!> files of whole datasets that checkpoints are (io_file_t), written or read by all ranks of a
!> communicator. In a plain file every HDF5 return code is recorded, not fatal: the first failed
!> call is kept and io_file_close returns one message, the same on every rank, for the caller
!> to stop the run cleanly.
module dkt_h5file
  use dkt_kinds, only: wp
  use mpi_f08, only: MPI_Comm, MPI_INFO_NULL, MPI_LOGICAL, MPI_INTEGER, MPI_CHARACTER, MPI_LOR, &
                     MPI_MIN, MPI_Comm_rank, MPI_Bcast, MPI_Allreduce
  use hdf5, only: hid_t, hsize_t, h5open_f, h5close_f, h5kind_to_type, H5_REAL_KIND, &
                  H5_INTEGER_KIND, h5fcreate_f, h5fopen_f, h5fclose_f, H5F_ACC_TRUNC_F, &
                  H5F_ACC_RDONLY_F, h5pcreate_f, h5pclose_f, H5P_FILE_ACCESS_F, &
                  H5P_DATASET_XFER_F, h5pset_fapl_mpio_f, h5pset_dxpl_mpio_f, &
                  H5FD_MPIO_COLLECTIVE_F, H5FD_MPIO_INDEPENDENT_F, h5eset_auto_f, h5lexists_f, &
                  h5screate_simple_f, h5sclose_f, h5sselect_hyperslab_f, h5sselect_none_f, &
                  h5sget_simple_extent_dims_f, h5sget_simple_extent_ndims_f, H5S_SELECT_SET_F, &
                  h5dcreate_f, h5dopen_f, h5dclose_f, h5dwrite_f, h5dread_f, h5dget_space_f, &
                  h5aexists_by_name_f, h5aopen_by_name_f, h5aread_f, h5aclose_f
  implicit none
  private
  public :: io_file_open, io_file_close, io_put_real, io_put_int, io_get_real, io_get_int, &
            io_dataset_dims, io_file_attribute, h5_real_attribute
  public :: h5_library_open, h5_file_opened, h5_file_closed

  !! and io_file_close reports it.
  type, public :: io_file_t
    integer(hid_t) :: file_id = -1
    integer(hid_t) :: dxpl = -1      !! transfer: collective to write, independent to read
    integer(hid_t) :: real_type = -1
    integer(hid_t) :: int_type = -1
    type(MPI_Comm) :: comm
    integer :: rank = 0
    logical :: writing = .false.
    character(len=:), allocatable :: path
    character(len=:), allocatable :: failed !! the first failed call, '' if none
  end type io_file_t

  !> Files open in this process (run files and plain files). The HDF5 library is process-global
  !> state: it is opened with the first file and closed with the last, so that closing one file
  !> never invalidates the identifiers of another (h5close_f closes every open object).
  integer :: n_open_files = 0

  integer(hsize_t), parameter :: one(1) = [1_hsize_t]

contains

  !> Open the HDF5 library unless a file holds it open already; hdferr < 0 when that failed.
  subroutine h5_library_open(hdferr)
    integer, intent(out) :: hdferr
    hdferr = 0
    if (n_open_files == 0) call h5open_f(hdferr)
  end subroutine h5_library_open

  !> Count a file that was opened (after h5_library_open).
  subroutine h5_file_opened()
    n_open_files = n_open_files + 1
  end subroutine h5_file_opened

  !> Count a file that was closed; the last one closes the HDF5 library (`closed`, with its
  !! return code in hdferr).
  subroutine h5_file_closed(closed, hdferr)
    logical, intent(out) :: closed
    integer, intent(out) :: hdferr
    n_open_files = n_open_files - 1
    closed = n_open_files == 0
    hdferr = 0
    if (closed) call h5close_f(hdferr)
  end subroutine h5_file_closed

  !> Open `path` for every rank of `comm`: created (truncated) when `writing`, else an existing
  !! file read-only. err is '' on success, else the same message on every rank and nothing is
  !! open. HDF5 prints no error stacks until io_file_close: the caller reports a failure.
  subroutine io_file_open(pf, path, comm, writing, err)
    type(io_file_t), intent(inout) :: pf
    character(len=*), intent(in) :: path
    type(MPI_Comm), intent(in) :: comm
    logical, intent(in) :: writing
    character(len=:), allocatable, intent(out) :: err
    integer(hid_t) :: fapl
    integer :: e(4), hdferr
    logical :: bad, any_bad

    err = ''
    pf%path = path
    pf%comm = comm
    pf%writing = writing
    pf%failed = ''
    call MPI_Comm_rank(comm, pf%rank)
    e = 0
    call h5_library_open(e(1))
    ! failures are reported as one message (err, io_file_close), not an HDF5 stack per rank
    call h5eset_auto_f(0, e(2))
    call h5pcreate_f(H5P_FILE_ACCESS_F, fapl, e(3))
    call h5pset_fapl_mpio_f(fapl, comm%MPI_VAL, MPI_INFO_NULL%MPI_VAL, e(4))
    bad = minval(e) < 0
    hdferr = -1
    if (.not. bad) then
      if (writing) then
        call h5fcreate_f(path, H5F_ACC_TRUNC_F, pf%file_id, hdferr, access_prp=fapl)
      else
        call h5fopen_f(path, H5F_ACC_RDONLY_F, pf%file_id, hdferr, access_prp=fapl)
      end if
      call h5pclose_f(fapl, e(1))
      bad = hdferr < 0 .or. e(1) < 0
    end if
    call MPI_Allreduce(bad, any_bad, 1, MPI_LOGICAL, MPI_LOR, comm)
    if (any_bad) then
      ! a file open on some ranks only stays open: closing it is collective and could hang
      call h5eset_auto_f(1, hdferr)
      if (writing) then
        err = 'cannot create '''//path//''''
      else
        err = 'cannot open '''//path//''' as an HDF5 file'
      end if
      return
    end if
    call h5_file_opened()
    pf%real_type = h5kind_to_type(wp, H5_REAL_KIND)
    pf%int_type = h5kind_to_type(kind(0), H5_INTEGER_KIND)
    call h5pcreate_f(H5P_DATASET_XFER_F, pf%dxpl, hdferr)
    call note(pf, hdferr, 'h5pcreate_f(transfer)')
    ! writes are collective (faster on a parallel file system); reads are independent, so
    ! that a rank that fails on a damaged file never leaves the others waiting in a read
    if (writing) then
      call h5pset_dxpl_mpio_f(pf%dxpl, H5FD_MPIO_COLLECTIVE_F, hdferr)
    else
      call h5pset_dxpl_mpio_f(pf%dxpl, H5FD_MPIO_INDEPENDENT_F, hdferr)
    end if
    call note(pf, hdferr, 'h5pset_dxpl_mpio_f')
  end subroutine io_file_open

  !> Close the file; err is '' when every call since it was opened succeeded on every rank,
  !! else the same message on every rank naming the file and the first failed call.
  subroutine io_file_close(pf, err)
    type(io_file_t), intent(inout) :: pf
    character(len=:), allocatable, intent(out) :: err
    integer :: hdferr, owner
    logical :: bad, any_bad, closed
    character(len=256) :: what

    err = ''
    if (pf%dxpl >= 0) then
      call h5pclose_f(pf%dxpl, hdferr)
      call note(pf, hdferr, 'h5pclose_f(transfer)')
    end if
    call h5fclose_f(pf%file_id, hdferr)
    call note(pf, hdferr, 'h5fclose_f')
    call h5_file_closed(closed, hdferr)
    if (closed) then
      call note(pf, hdferr, 'h5close_f')
    else
      call h5eset_auto_f(1, hdferr)
      call note(pf, hdferr, 'h5eset_auto_f')
    end if
    pf%file_id = -1
    pf%dxpl = -1
    bad = len(pf%failed) > 0
    call MPI_Allreduce(bad, any_bad, 1, MPI_LOGICAL, MPI_LOR, pf%comm)
    if (.not. any_bad) return
    ! the message of the lowest rank that failed, so all ranks say the same
    call MPI_Allreduce(merge(pf%rank, huge(0), bad), owner, 1, MPI_INTEGER, MPI_MIN, pf%comm)
    what = ''
    if (bad) what = pf%failed
    call MPI_Bcast(what, len(what), MPI_CHARACTER, owner, pf%comm)
    err = 'HDF5 call '//trim(what)//' failed on '''//pf%path//''''
  end subroutine io_file_close

  !> Record the first failed call.
  subroutine note(pf, hdferr, what)
    type(io_file_t), intent(inout) :: pf
    integer, intent(in) :: hdferr
    character(len=*), intent(in) :: what
    if (hdferr < 0 .and. len(pf%failed) == 0) pf%failed = what
  end subroutine note

  !> The real attribute `aname` of the object at `obj` (a path) in the open HDF5 file
  !! `file_id`, read by this rank alone; found = .false. when there is none or it is not a number.
  subroutine h5_real_attribute(file_id, obj, aname, value, found)
    integer(hid_t), intent(in) :: file_id
    character(len=*), intent(in) :: obj, aname
    real(wp), intent(out) :: value
    logical, intent(out) :: found
    integer(hid_t) :: attr
    integer :: hdferr, e
    value = 0.0_wp
    call h5aexists_by_name_f(file_id, obj, aname, found, hdferr)
    if (hdferr < 0 .or. .not. found) then
      found = .false.
      return
    end if
    call h5aopen_by_name_f(file_id, obj, aname, attr, hdferr)
    if (hdferr < 0) then
      found = .false.
      return
    end if
    call h5aread_f(attr, h5kind_to_type(wp, H5_REAL_KIND), value, one, hdferr)
    found = hdferr >= 0
    call h5aclose_f(attr, e)
  end subroutine h5_real_attribute

  !> The real attribute `aname` of the object `obj` of the plain file `pf`, as h5_real_attribute.
  subroutine io_file_attribute(pf, obj, aname, value, found)
    type(io_file_t), intent(in) :: pf
    character(len=*), intent(in) :: obj, aname
    real(wp), intent(out) :: value
    logical, intent(out) :: found
    call h5_real_attribute(pf%file_id, obj, aname, value, found)
  end subroutine io_file_attribute

  !> The dimensions of dataset `name` in Fortran order (h5py's reversed): ndims = -1 when there
  !! is no such dataset or its shape cannot be read (a damaged file).
  subroutine io_dataset_dims(pf, name, ndims, dims)
    type(io_file_t), intent(inout) :: pf
    character(len=*), intent(in) :: name
    integer, intent(out) :: ndims
    integer(hsize_t), intent(out) :: dims(3) !! the first ndims are set
    integer(hid_t) :: dset, space
    integer(hsize_t) :: maxdims(3)
    integer :: hdferr
    logical :: exists
    ndims = -1
    dims = 0
    if (len(pf%failed) > 0) return
    call h5lexists_f(pf%file_id, name, exists, hdferr)
    if (hdferr < 0 .or. .not. exists) return
    call h5dopen_f(pf%file_id, name, dset, hdferr)
    if (hdferr < 0) return
    call h5dget_space_f(dset, space, hdferr)
    if (hdferr >= 0) then
      call h5sget_simple_extent_ndims_f(space, ndims, hdferr)
      if (hdferr < 0 .or. ndims > 3 .or. ndims < 0) then
        ndims = -1
      else if (ndims > 0) then
        call h5sget_simple_extent_dims_f(space, dims(1:ndims), maxdims(1:ndims), hdferr)
        if (hdferr < 0) ndims = -1
      end if
      call h5sclose_f(space, hdferr)
      call note(pf, hdferr, 'h5sclose_f('//name//')')
    else
      ndims = -1
    end if
    call h5dclose_f(dset, hdferr)
    call note(pf, hdferr, 'h5dclose_f('//name//')')
  end subroutine io_dataset_dims

  !> Create the real dataset `name` of dimensions `dims` (Fortran order); this rank writes its
  !! block (start, count) from `values` when `mine`, and nothing otherwise. Collective.
  subroutine io_put_real(pf, name, dims, start, count, values, mine)
    type(io_file_t), intent(inout) :: pf
    character(len=*), intent(in) :: name
    integer(hsize_t), intent(in) :: dims(:), start(:), count(:)
    real(wp), intent(in) :: values(*)
    logical, intent(in) :: mine
    call put_block(pf, name, pf%real_type, dims, start, count, mine, r=values)
  end subroutine io_put_real

  !> Create the 1-D integer dataset `name` holding rank 0's `values`. Collective.
  subroutine io_put_int(pf, name, values)
    type(io_file_t), intent(inout) :: pf
    character(len=*), intent(in) :: name
    integer, intent(in) :: values(:)
    integer(hsize_t) :: n(1)
    n = size(values, kind=hsize_t)
    call put_block(pf, name, pf%int_type, n, [0_hsize_t], n, pf%rank == 0, i=values)
  end subroutine io_put_int

  !> Every rank makes the same calls in the same order, even after a failure, because dataset
  !! creation and collective writes need all ranks; io_file_close reports the failure.
  subroutine put_block(pf, name, htype, dims, start, count, mine, r, i)
    type(io_file_t), intent(inout) :: pf
    character(len=*), intent(in) :: name
    integer(hid_t), intent(in) :: htype
    integer(hsize_t), intent(in) :: dims(:), start(:), count(:)
    logical, intent(in) :: mine
    real(wp), intent(in), optional :: r(*)
    integer, intent(in), optional :: i(*)
    integer(hid_t) :: space, dset, mspace
    integer(hsize_t) :: n
    integer :: hdferr
    real(wp) :: rdummy(1)
    integer :: idummy(1)

    n = product(count)
    call h5screate_simple_f(size(dims), dims, space, hdferr)
    call note(pf, hdferr, 'h5screate_simple_f('//name//')')
    call h5dcreate_f(pf%file_id, name, htype, space, dset, hdferr)
    call note(pf, hdferr, 'h5dcreate_f('//name//')')
    if (mine .and. n > 0) then
      mspace = select_block(pf, space, start, count, name)
      if (present(r)) then
        call h5dwrite_f(dset, htype, r(1:n), count, hdferr, mem_space_id=mspace, &
                        file_space_id=space, xfer_prp=pf%dxpl)
      else
        call h5dwrite_f(dset, htype, i(1:n), count, hdferr, mem_space_id=mspace, &
                        file_space_id=space, xfer_prp=pf%dxpl)
      end if
    else
      call h5sselect_none_f(space, hdferr)
      call note(pf, hdferr, 'h5sselect_none_f('//name//')')
      call h5screate_simple_f(1, one, mspace, hdferr)
      call note(pf, hdferr, 'h5screate_simple_f('//name//')')
      call h5sselect_none_f(mspace, hdferr)
      call note(pf, hdferr, 'h5sselect_none_f('//name//')')
      rdummy = 0.0_wp
      idummy = 0
      if (present(r)) then
        call h5dwrite_f(dset, htype, rdummy, one, hdferr, mem_space_id=mspace, &
                        file_space_id=space, xfer_prp=pf%dxpl)
      else
        call h5dwrite_f(dset, htype, idummy, one, hdferr, mem_space_id=mspace, &
                        file_space_id=space, xfer_prp=pf%dxpl)
      end if
    end if
    call note(pf, hdferr, 'h5dwrite_f('//name//')')
    call h5sclose_f(mspace, hdferr)
    call note(pf, hdferr, 'h5sclose_f('//name//')')
    call h5sclose_f(space, hdferr)
    call note(pf, hdferr, 'h5sclose_f('//name//')')
    call h5dclose_f(dset, hdferr)
    call note(pf, hdferr, 'h5dclose_f('//name//')')
  end subroutine put_block

  !> Select block (start, count) of the file space `space` of dataset `name`; returns the
  !! memory space of the block.
  function select_block(pf, space, start, count, name) result(mspace)
    type(io_file_t), intent(inout) :: pf
    integer(hid_t), intent(in) :: space
    integer(hsize_t), intent(in) :: start(:), count(:)
    character(len=*), intent(in) :: name
    integer(hid_t) :: mspace
    integer :: hdferr
    call h5sselect_hyperslab_f(space, H5S_SELECT_SET_F, start, count, hdferr)
    call note(pf, hdferr, 'h5sselect_hyperslab_f('//name//')')
    call h5screate_simple_f(size(count), count, mspace, hdferr)
    call note(pf, hdferr, 'h5screate_simple_f('//name//')')
  end function select_block

  !> Read block (start, count) of the real dataset `name` into values(1:product(count)). The
  !! caller has checked the dataset's dimensions (io_dataset_dims). Skipped after a failure.
  subroutine io_get_real(pf, name, start, count, values)
    type(io_file_t), intent(inout) :: pf
    character(len=*), intent(in) :: name
    integer(hsize_t), intent(in) :: start(:), count(:)
    real(wp), intent(inout) :: values(*)
    call get_block(pf, name, pf%real_type, start, count, r=values)
  end subroutine io_get_real

  !> Read the first size(values) entries of the 1-D integer dataset `name`.
  subroutine io_get_int(pf, name, values)
    type(io_file_t), intent(inout) :: pf
    character(len=*), intent(in) :: name
    integer, intent(inout) :: values(:)
    call get_block(pf, name, pf%int_type, [0_hsize_t], [size(values, kind=hsize_t)], i=values)
  end subroutine io_get_int

  subroutine get_block(pf, name, htype, start, count, r, i)
    type(io_file_t), intent(inout) :: pf
    character(len=*), intent(in) :: name
    integer(hid_t), intent(in) :: htype
    integer(hsize_t), intent(in) :: start(:), count(:)
    real(wp), intent(inout), optional :: r(*)
    integer, intent(inout), optional :: i(*)
    integer(hid_t) :: dset, space, mspace
    integer(hsize_t) :: n
    integer :: hdferr

    n = product(count)
    if (len(pf%failed) > 0 .or. n == 0) return
    call h5dopen_f(pf%file_id, name, dset, hdferr)
    call note(pf, hdferr, 'h5dopen_f('//name//')')
    if (hdferr < 0) return
    call h5dget_space_f(dset, space, hdferr)
    call note(pf, hdferr, 'h5dget_space_f('//name//')')
    if (hdferr >= 0) then
      mspace = select_block(pf, space, start, count, name)
      if (len(pf%failed) == 0) then
        if (present(r)) then
          call h5dread_f(dset, htype, r(1:n), count, hdferr, mem_space_id=mspace, &
                         file_space_id=space, xfer_prp=pf%dxpl)
        else
          call h5dread_f(dset, htype, i(1:n), count, hdferr, mem_space_id=mspace, &
                         file_space_id=space, xfer_prp=pf%dxpl)
        end if
        call note(pf, hdferr, 'h5dread_f('//name//')')
        call h5sclose_f(mspace, hdferr)
        call note(pf, hdferr, 'h5sclose_f('//name//')')
      end if
      call h5sclose_f(space, hdferr)
      call note(pf, hdferr, 'h5sclose_f('//name//')')
    end if
    call h5dclose_f(dset, hdferr)
    call note(pf, hdferr, 'h5dclose_f('//name//')')
  end subroutine get_block

end module dkt_h5file

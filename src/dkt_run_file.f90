!> The run file `<dir>/<name>.h5` as an open object (io_t) and the layer the writers of dkt_io
!> and the restart cut of dkt_io_reopen build on: the open they share (run_file_open), flush and
!> close, the rows of series and tables held in memory and appended many at a time, groups made
!> on demand, scalar attributes and collective block writes. Every HDF5 return code is checked:
!> a failed call stops the job (check). Collective over the communicator of the open file.
module dkt_run_file
  use iso_c_binding, only: c_null_char, c_ptr, c_loc, c_int, c_int64_t, c_size_t
  use dkt_kinds, only: wp
  use dkt_errors, only: fatal_local
  use dkt_h5file, only: h5_library_open, h5_file_opened, h5_file_closed
  use dkt_xdmf, only: xdmf_t, xdmf_init, xdmf_free
  use mpi_f08, only: MPI_Comm, MPI_INFO_NULL, MPI_LOGICAL, MPI_INTEGER, MPI_LOR, MPI_SUM, &
                     MPI_Comm_rank, MPI_Bcast, MPI_Allreduce
  use hdf5, only: hid_t, hsize_t, h5kind_to_type, H5_REAL_KIND, H5_INTEGER_KIND, h5fcreate_f, &
                  h5fclose_f, h5fflush_f, H5F_ACC_EXCL_F, H5F_ACC_TRUNC_F, H5F_SCOPE_GLOBAL_F, &
                  h5pcreate_f, h5pclose_f, H5P_FILE_ACCESS_F, H5P_DATASET_XFER_F, &
                  H5P_DATASET_CREATE_F, h5pset_fapl_mpio_f, h5pset_dxpl_mpio_f, &
                  H5FD_MPIO_COLLECTIVE_F, h5eset_auto_f, h5pset_coll_metadata_write_f, &
                  h5pset_all_coll_metadata_ops_f, h5pset_chunk_f, h5gcreate_f, h5oopen_f, &
                  h5oclose_f, h5lexists_f, h5aexists_f, h5adelete_f, h5screate_f, &
                  h5screate_simple_f, h5sclose_f, &
                  h5sselect_hyperslab_f, h5sselect_none_f, h5sget_simple_extent_dims_f, &
                  h5sget_simple_extent_ndims_f, H5S_SCALAR_F, H5S_SELECT_SET_F, H5S_UNLIMITED_F, &
                  h5dcreate_f, h5dopen_f, h5dclose_f, h5dwrite_f, h5dget_space_f, &
                  h5dset_extent_f, h5acreate_f, h5awrite_f, h5aclose_f, h5tcopy_f, h5tclose_f, &
                  H5T_NATIVE_CHARACTER, h5fopen_f, H5F_ACC_RDWR_F, h5tset_cset_f, &
                  H5T_CSET_UTF8_F
  implicit none
  private
  public :: io_close, io_flush, io_file_exists, run_file_open, require_open, check, &
            field_group, find_pending, hold_rows, flush_pending, open_object, put_attr, one, &
            delete_attribute

  !> The rows appended to one extendible dataset since the last io_flush.
  type :: pending_t
    character(len=:), allocatable :: group !! e.g. 'particles'
    character(len=:), allocatable :: name  !! e.g. 'x'
    integer :: ndims = 1 !! 1 series, 2 table
    integer :: n = 0     !! rows held
    character(len=:), allocatable :: units !! the dataset's `units` attribute, '' = none
    real(wp), allocatable :: rows(:, :) !! (columns, capacity)
  end type pending_t

  !> A dataset's store holds at most MAX_PENDING rows and PENDING_VALUES values (512 KiB)
  integer, parameter :: PENDING_VALUES = 65536, MAX_PENDING = 256

  !> An open output file and what has been written to it.
  type, public :: io_t
    logical :: is_open = .false.
    integer(hid_t) :: file_id = -1
    integer(hid_t) :: dxpl = -1      !! collective transfer property list
    integer(hid_t) :: real_type = -1 !! file and memory type of real(wp)
    integer(hid_t) :: int_type = -1  !! file and memory type of default integer
    type(MPI_Comm) :: comm !! the writing ranks
    integer :: rank = 0
    integer :: nx = 0  !! global columns
    integer :: ny = 0  !! global rows
    integer :: y0 = 0  !! rows below this rank's slab
    integer :: nyl = 0 !! rows of this rank's slab (may be 0)
    real(wp) :: dx = 0.0_wp !! cm, lattice spacing
    integer :: compress = 0 !! deflate level of the field datasets, 0 = none
    character(len=:), allocatable :: name      !! file base name, no extension
    character(len=:), allocatable :: path      !! <dir>/<name>.h5
    character(len=:), allocatable :: xdmf_path !! <dir>/<name>.xdmf
    type(xdmf_t) :: xdmf !! the snapshots listed in the sidecar
    !> Rows of the extendible datasets not yet in the file, one entry per dataset in the order
    !! of first use. Every append is collective in parallel HDF5 (the extent is file metadata),
    !! so rows are gathered here and written many at a time (io_flush).
    type(pending_t), allocatable :: pending(:)
    integer :: npending = 0
  end type io_t

  integer(hsize_t), parameter :: one(1) = [1_hsize_t]

  interface
    !> H5Tset_size of the C library, which takes H5T_VARIABLE = (size_t) -1. hid_t is the C
    !! library's int64_t (HDF5 >= 1.10); integer(hid_t) is the same kind but not declared
    !! interoperable, so the identifier is passed as c_int64_t.
    integer(c_int) function h5tset_size_variable(type_id, size) bind(c, name='H5Tset_size')
      import :: c_int, c_int64_t, c_size_t
      integer(c_int64_t), value :: type_id
      integer(c_size_t), value :: size
    end function h5tset_size_variable
  end interface

contains
  !> The open that io_open and io_reopen share: name the files `<dir>/<name>.h5` and
  !! `<dir>/<name>.xdmf`, check that the slabs tile the rows, then create the file (`resume`
  !! false: refused when it exists, unless `overwrite`) or open the existing one for writing
  !! (`resume` true: refused when it is missing), with parallel access, and set up the io_t
  !! (set_open). err is '' on success, else the same message on every rank, and nothing is
  !! open.
  subroutine run_file_open(io, dir, name, comm, nx, ny, y0, nyl, dx, resume, overwrite, err)
    type(io_t), intent(inout) :: io
    character(len=*), intent(in) :: dir  !! output directory (exists)
    character(len=*), intent(in) :: name !! file base name, e.g. the namelist basename
    type(MPI_Comm), intent(in) :: comm   !! the ranks that write; all call run_file_open
    integer, intent(in) :: nx, ny        !! global lattice size (columns, rows)
    integer, intent(in) :: y0, nyl       !! this rank holds global rows y0+1 .. y0+nyl
    real(wp), intent(in) :: dx           !! cm, lattice spacing (for the XDMF geometry)
    logical, intent(in) :: resume        !! open the file of the run to resume
    logical, intent(in) :: overwrite     !! replace an existing file (resume = .false.)
    character(len=:), allocatable, intent(out) :: err
    integer(hid_t) :: fapl
    integer :: hdferr, rows
    logical :: bad, any_bad, exists

    err = ''
    call MPI_Comm_rank(comm, io%rank)
    io%name = trim(name)
    io%path = trim(dir)//'/'//io%name//'.h5'
    io%xdmf_path = trim(dir)//'/'//io%name//'.xdmf'

    ! The slabs must tile the rows exactly; a wrong tiling would leave holes in the file.
    bad = nx < 1 .or. ny < 1 .or. y0 < 0 .or. nyl < 0 .or. y0 + nyl > ny .or. &
          .not. dx > 0.0_wp .or. len_trim(name) == 0
    call MPI_Allreduce(bad, any_bad, 1, MPI_LOGICAL, MPI_LOR, comm)
    call MPI_Allreduce(nyl, rows, 1, MPI_INTEGER, MPI_SUM, comm)
    if (any_bad .or. rows /= ny) then
      err = 'cannot open '''//io%path//''': the slab rows (y0, nyl) do not tile the '// &
            'ny rows, or nx, ny, dx or the name is invalid'
      return
    end if

    ! Rank 0 alone looks, so every rank acts on the same answer.
    if (io%rank == 0) exists = io_file_exists(io%path)
    call MPI_Bcast(exists, 1, MPI_LOGICAL, 0, comm)
    if (resume .and. .not. exists) then
      err = 'the output file '''//io%path//''' of the run to resume is missing; a restart '// &
            'continues the output file of the run that wrote the checkpoint (same output.dir)'
      return
    else if (.not. resume .and. exists .and. .not. overwrite) then
      err = 'output file '''//io%path//''' exists; set output.overwrite = .true. '// &
            'or choose another output.dir'
      return
    end if

    call h5_library_open(hdferr)
    call check(hdferr, 'h5open_f', io%path)
    fapl = parallel_access(io, comm)
    ! A failed create or open is reported as err below (one message, not an HDF5 stack per rank).
    call h5eset_auto_f(0, hdferr)
    call check(hdferr, 'h5eset_auto_f', io%path)
    if (resume) then
      call h5fopen_f(io%path, H5F_ACC_RDWR_F, io%file_id, hdferr, access_prp=fapl)
    else if (exists) then
      call h5fcreate_f(io%path, H5F_ACC_TRUNC_F, io%file_id, hdferr, access_prp=fapl)
    else
      ! EXCL when the file should not exist, so a file that appeared meanwhile is not clobbered.
      call h5fcreate_f(io%path, H5F_ACC_EXCL_F, io%file_id, hdferr, access_prp=fapl)
    end if
    bad = hdferr < 0
    call h5eset_auto_f(1, hdferr)
    call check(hdferr, 'h5eset_auto_f', io%path)
    call h5pclose_f(fapl, hdferr)
    call check(hdferr, 'h5pclose_f(file access)', io%path)
    call MPI_Allreduce(bad, any_bad, 1, MPI_LOGICAL, MPI_LOR, comm)
    if (any_bad) then
      ! HDF5 stays open: should the create have succeeded on some ranks only, closing the
      ! library would close that file collectively, and hang; the caller stops the run anyway.
      if (resume) then
        err = 'cannot open '''//io%path//''' to continue it'
      else
        err = 'cannot create output file '''//io%path//'''; check that output.dir exists '// &
              'and is writable'
      end if
      return
    end if
    call h5_file_opened()
    call set_open(io, comm, nx, ny, y0, nyl, dx)
  end subroutine run_file_open

  !> Write the rows held for the extendible datasets (io_write_series, io_write_table) and
  !! flush the file, so that it holds every sample given so far (called before a checkpoint,
  !! so that a resumed run finds the samples the checkpoint counts). Collective.
  subroutine io_flush(io)
    type(io_t), intent(inout) :: io
    integer :: hdferr

    call require_open(io, 'io_flush')
    call flush_pending(io)
    call h5fflush_f(io%file_id, H5F_SCOPE_GLOBAL_F, hdferr)
    call check(hdferr, 'h5fflush_f', io%path)
  end subroutine io_flush

  !> Flush and close the file; the last file closed also closes the HDF5 library.
  subroutine io_close(io)
    type(io_t), intent(inout) :: io
    integer :: hdferr
    logical :: closed

    if (.not. io%is_open) return
    call flush_pending(io)
    call h5fflush_f(io%file_id, H5F_SCOPE_GLOBAL_F, hdferr)
    call check(hdferr, 'h5fflush_f', io%path)
    call h5pclose_f(io%dxpl, hdferr)
    call check(hdferr, 'h5pclose_f(transfer)', io%path)
    call h5fclose_f(io%file_id, hdferr)
    call check(hdferr, 'h5fclose_f', io%path)
    call h5_file_closed(closed, hdferr)
    if (closed) call check(hdferr, 'h5close_f', io%path)
    io%is_open = .false.
    io%file_id = -1
    io%dxpl = -1
    call xdmf_free(io%xdmf)
    if (allocated(io%pending)) deallocate (io%pending)
    io%npending = 0
  end subroutine io_close

  !> Whether a file exists at `path` (local to the calling rank).
  logical function io_file_exists(path)
    character(len=*), intent(in) :: path
    inquire (file=path, exist=io_file_exists)
  end function io_file_exists

  !> File access for parallel I/O on `comm`, metadata written and read collectively (one rank
  !! does the I/O instead of all of them). The caller closes it.
  function parallel_access(io, comm) result(fapl)
    type(io_t), intent(in) :: io
    type(MPI_Comm), intent(in) :: comm
    integer(hid_t) :: fapl
    integer :: hdferr
    call h5pcreate_f(H5P_FILE_ACCESS_F, fapl, hdferr)
    call check(hdferr, 'h5pcreate_f(file access)', io%path)
    call h5pset_fapl_mpio_f(fapl, comm%MPI_VAL, MPI_INFO_NULL%MPI_VAL, hdferr)
    call check(hdferr, 'h5pset_fapl_mpio_f', io%path)
    call h5pset_coll_metadata_write_f(fapl, .true., hdferr)
    call check(hdferr, 'h5pset_coll_metadata_write_f', io%path)
    call h5pset_all_coll_metadata_ops_f(fapl, .true., hdferr)
    call check(hdferr, 'h5pset_all_coll_metadata_ops_f', io%path)
  end function parallel_access

  !> The state of an io_t whose file was just opened: collective transfers, types, the slab.
  subroutine set_open(io, comm, nx, ny, y0, nyl, dx)
    type(io_t), intent(inout) :: io
    type(MPI_Comm), intent(in) :: comm
    integer, intent(in) :: nx, ny, y0, nyl
    real(wp), intent(in) :: dx
    integer :: hdferr
    call h5pcreate_f(H5P_DATASET_XFER_F, io%dxpl, hdferr)
    call check(hdferr, 'h5pcreate_f(transfer)', io%path)
    call h5pset_dxpl_mpio_f(io%dxpl, H5FD_MPIO_COLLECTIVE_F, hdferr)
    call check(hdferr, 'h5pset_dxpl_mpio_f', io%path)
    io%real_type = h5kind_to_type(wp, H5_REAL_KIND)
    io%int_type = h5kind_to_type(kind(0), H5_INTEGER_KIND)
    io%comm = comm
    io%nx = nx
    io%ny = ny
    io%y0 = y0
    io%nyl = nyl
    io%dx = dx
    call xdmf_init(io%xdmf, io%xdmf_path, io%name//'.h5', nx, ny, dx)
    io%npending = 0
    io%is_open = .true.
  end subroutine set_open

  !> Group of the fields of `step`: six digits, more when the step needs them.
  function field_group(step) result(gname)
    integer, intent(in) :: step
    character(len=:), allocatable :: gname
    character(len=24) :: digits
    write (digits, '(i6.6)') step
    if (step > 999999) write (digits, '(i0)') step
    gname = '/fields/'//trim(digits)
  end function field_group

  !> Append one sample to each extendible dataset /<group>/<names(k)>, created (chunked: only
  !! chunked datasets can grow) on first use. Samples run along the last HDF5 dimension, so h5py
  !! sees (n_samples,) for a series (`ndims` = 1, values(1, k) the new value) and (n_samples,
  !! ncols) for a table (`ndims` = 2, values(:, k) the new row). Rank 0 writes the sample; the
  !! other ranks join the collective writes with nothing selected.
  !> The entry of io%pending that holds /<group>/<name>, 0 if none.
  integer function find_pending(io, group, name) result(idx)
    type(io_t), intent(in) :: io
    character(len=*), intent(in) :: group, name
    do idx = 1, io%npending
      if (io%pending(idx)%name == trim(name)) then
        if (io%pending(idx)%group == trim(group)) return
      end if
    end do
    idx = 0
  end function find_pending

  !> Hold values(:, k) as the next row of /<group>/<names(k)>, k = 1..size(names). A dataset
  !! keeps the kind (series or table) and the column count of its first row. When a dataset's
  !! store is full, every held row is written (on every rank at the same call: the calls are
  !! collective, so the stores fill together).
  subroutine hold_rows(io, group, names, values, ndims, caller, units)
    type(io_t), intent(inout) :: io
    character(len=*), intent(in) :: group, names(:)
    real(wp), intent(in) :: values(:, :) !! (ncols, size(names)); ncols = 1 for a series
    integer, intent(in) :: ndims         !! 1 series, 2 table
    character(len=*), intent(in) :: caller
    character(len=*), intent(in), optional :: units(:) !! of a dataset created from here
    type(pending_t), allocatable :: grown(:)
    integer :: k, idx, ncols
    logical :: full

    ncols = size(values, 1)
    full = .false.
    do k = 1, size(names)
      idx = find_pending(io, group, names(k))
      if (idx == 0) then
        if (.not. allocated(io%pending)) allocate (io%pending(8))
        if (io%npending == size(io%pending)) then
          allocate (grown(2*size(io%pending)))
          grown(1:io%npending) = io%pending
          call move_alloc(grown, io%pending)
        end if
        io%npending = io%npending + 1
        idx = io%npending
        io%pending(idx)%group = trim(group)
        io%pending(idx)%name = trim(names(k))
        io%pending(idx)%ndims = ndims
        io%pending(idx)%n = 0
        io%pending(idx)%units = ''
        if (present(units)) io%pending(idx)%units = trim(units(k))
        allocate (io%pending(idx)%rows(ncols, max(1, min(MAX_PENDING, PENDING_VALUES/ncols))))
      end if
      associate (p => io%pending(idx))
        call require_shape(io, caller, p%group//'/'//p%name, p%ndims, size(p%rows, 1), ndims, &
                           ncols)
        p%n = p%n + 1
        p%rows(:, p%n) = values(:, k)
        full = full .or. p%n == size(p%rows, 2)
      end associate
    end do
    if (full) call flush_pending(io)
  end subroutine hold_rows

  !> Stop the run when rows of kind `ndims` (1 series, 2 table) and `ncols` columns go to the
  !! dataset `what`, which has `has_ndims` dimensions and `has_cols` columns (the file's
  !! dataset, or the rows held for it).
  subroutine require_shape(io, caller, what, has_ndims, has_cols, ndims, ncols)
    type(io_t), intent(in) :: io
    character(len=*), intent(in) :: caller, what
    integer, intent(in) :: has_ndims, has_cols, ndims, ncols
    character(len=80) :: msg

    if (has_ndims /= ndims) then
      write (msg, '(a,i0,a)') ' has ', has_ndims, ' dimensions; write it with '// &
        trim(merge('io_write_series', 'io_write_table ', has_ndims == 1))
    else if (has_cols /= ncols) then
      write (msg, '(a,i0,a,i0)') ' has ', has_cols, ' columns; the new row has ', ncols
    else
      return
    end if
    call fatal_local(caller//': '//what//' in '''//io%path//''''//trim(msg))
  end subroutine require_shape

  !> Append the held rows to their datasets, in the order the datasets were first used, and
  !! empty the stores. Collective.
  subroutine flush_pending(io)
    type(io_t), intent(inout) :: io
    integer :: idx
    do idx = 1, io%npending
      if (io%pending(idx)%n > 0) call write_rows(io, io%pending(idx))
      io%pending(idx)%n = 0
    end do
  end subroutine flush_pending

  !> Append the rows held in p to the extendible dataset /<p%group>/<p%name>, created with its
  !! group on first use: 1-D (samples) for a series, 2-D (columns, samples) for a table. A
  !! dataset already in the file (a resumed run appends to the run it continues) must be of
  !! the same kind and column count.
  subroutine write_rows(io, p)
    type(io_t), intent(in) :: io
    type(pending_t), intent(in) :: p
    integer(hid_t) :: grp, dcpl, fspace, dset
    integer(hsize_t) :: ncols, nrows, dims(2), maxdims(2), chunk(2), start(2), count(2)
    integer :: hdferr, lo, stored, ndims
    logical :: exists
    character(len=:), allocatable :: what, caller

    ! A series uses the last entry of the (column, sample) arrays only.
    ndims = p%ndims
    lo = 3 - ndims
    ncols = size(p%rows, 1, kind=hsize_t)
    nrows = int(p%n, hsize_t)
    caller = trim(merge('io_write_series', 'io_write_table ', ndims == 1))
    what = p%group//'/'//p%name
    grp = open_object(io, p%group)
    call h5lexists_f(grp, p%name, exists, hdferr)
    call check(hdferr, 'h5lexists_f('//what//')', io%path)
    if (exists) then
      call h5dopen_f(grp, p%name, dset, hdferr)
      call check(hdferr, 'h5dopen_f('//what//')', io%path)
    else
      dims = [ncols, 0_hsize_t]
      maxdims = [ncols, H5S_UNLIMITED_F]
      ! Whole rows, about 1024 values (8 KiB) a chunk.
      chunk = [ncols, max(1_hsize_t, 1024_hsize_t/ncols)]
      call h5screate_simple_f(ndims, dims(lo:), fspace, hdferr, maxdims=maxdims(lo:))
      call check(hdferr, 'h5screate_simple_f', io%path)
      call h5pcreate_f(H5P_DATASET_CREATE_F, dcpl, hdferr)
      call check(hdferr, 'h5pcreate_f(dataset create)', io%path)
      call h5pset_chunk_f(dcpl, ndims, chunk(lo:), hdferr)
      call check(hdferr, 'h5pset_chunk_f', io%path)
      call h5dcreate_f(grp, p%name, io%real_type, fspace, dset, hdferr, dcpl_id=dcpl)
      call check(hdferr, 'h5dcreate_f('//what//')', io%path)
      if (len(p%units) > 0) call put_attr(io, dset, 'units', s=p%units)
      call h5pclose_f(dcpl, hdferr)
      call check(hdferr, 'h5pclose_f', io%path)
      call h5sclose_f(fspace, hdferr)
      call check(hdferr, 'h5sclose_f', io%path)
    end if
    call h5dget_space_f(dset, fspace, hdferr)
    call check(hdferr, 'h5dget_space_f('//what//')', io%path)
    call h5sget_simple_extent_ndims_f(fspace, stored, hdferr)
    call check(hdferr, 'h5sget_simple_extent_ndims_f('//what//')', io%path)
    call require_shape(io, caller, what, stored, 1, ndims, 1)
    call h5sget_simple_extent_dims_f(fspace, dims(lo:), maxdims(lo:), hdferr)
    call check(min(hdferr, 0), 'h5sget_simple_extent_dims_f('//what//')', io%path)
    call h5sclose_f(fspace, hdferr)
    call check(hdferr, 'h5sclose_f', io%path)
    if (ndims == 2) call require_shape(io, caller, what, 2, int(dims(1)), 2, int(ncols))
    dims(2) = dims(2) + nrows
    call h5dset_extent_f(dset, dims(lo:), hdferr)
    call check(hdferr, 'h5dset_extent_f('//what//')', io%path)
    start = [0_hsize_t, dims(2) - nrows]
    count = merge([ncols, nrows], [0_hsize_t, 0_hsize_t], io%rank == 0)
    call write_block(io, dset, start(lo:), count(lo:), p%rows, what)
    call h5dclose_f(dset, hdferr)
    call check(hdferr, 'h5dclose_f('//what//')', io%path)
    call h5oclose_f(grp, hdferr)
    call check(hdferr, 'h5oclose_f('//p%group//')', io%path)
  end subroutine write_rows

  !> Remove the attribute `name` of the open object `obj` (at `path`), if it has one.
  subroutine delete_attribute(io, obj, path, name)
    type(io_t), intent(in) :: io
    integer(hid_t), intent(in) :: obj
    character(len=*), intent(in) :: path, name
    integer :: hdferr
    logical :: exists
    call h5aexists_f(obj, name, exists, hdferr)
    call check(hdferr, 'h5aexists_f('//path//' '//name//')', io%path)
    if (exists) then
      call h5adelete_f(obj, name, hdferr)
      call check(hdferr, 'h5adelete_f('//path//' '//name//')', io%path)
    end if
  end subroutine delete_attribute

  !> Open the group or dataset at `path` ('a/b' or '/a/b'; '' or '/' is the root group),
  !! creating each missing component as a group. The caller closes it with h5oclose_f.
  function open_object(io, path) result(obj)
    type(io_t), intent(in) :: io
    character(len=*), intent(in) :: path
    integer(hid_t) :: obj, parent
    integer :: hdferr, first, last
    logical :: exists

    call h5oopen_f(io%file_id, '/', obj, hdferr)
    call check(hdferr, 'h5oopen_f(/)', io%path)
    first = 1
    do while (first <= len_trim(path))
      last = first + index(path(first:len_trim(path))//'/', '/') - 2 ! component first..last
      if (last >= first) then
        parent = obj
        call h5lexists_f(parent, path(first:last), exists, hdferr)
        call check(hdferr, 'h5lexists_f('//path(:last)//')', io%path)
        if (exists) then
          call h5oopen_f(parent, path(first:last), obj, hdferr)
        else
          call h5gcreate_f(parent, path(first:last), obj, hdferr)
        end if
        call check(hdferr, 'h5oopen_f/h5gcreate_f('//path(:last)//')', io%path)
        call h5oclose_f(parent, hdferr)
        call check(hdferr, 'h5oclose_f', io%path)
      end if
      first = last + 2
    end do
  end function open_object

  subroutine require_open(io, caller)
    type(io_t), intent(in) :: io
    character(len=*), intent(in) :: caller
    if (.not. io%is_open) call fatal_local(caller//': no output file is open; call io_open first')
  end subroutine require_open

  !> Stop the run on a failed HDF5 call; HDF5 has printed its error stack above the message.
  subroutine check(hdferr, what, path)
    integer, intent(in) :: hdferr
    character(len=*), intent(in) :: what, path
    if (hdferr < 0) call fatal_local('HDF5 call '//what//' failed on '''//path// &
                                     '''; is the disk full or the file system read-only?')
  end subroutine check

  !> Write the new scalar attribute `name` of object `loc`: a real(wp) r, an integer i or a string
  !! s, whichever is present (one is). A string is a variable-length UTF-8 string (h5py: str).
  subroutine put_attr(io, loc, name, r, i, s)
    type(io_t), intent(in) :: io
    integer(hid_t), intent(in) :: loc
    character(len=*), intent(in) :: name
    real(wp), intent(in), optional :: r
    integer, intent(in), optional :: i
    character(len=*), intent(in), optional :: s
    integer(hid_t) :: atype, space, attr
    integer :: hdferr, e(3)
    character(len=:), allocatable, target :: text
    type(c_ptr), target :: ptr

    if (present(r)) then
      atype = io%real_type
    else if (present(i)) then
      atype = io%int_type
    else
      ! the Fortran wrapper of H5Tset_size cannot pass H5T_VARIABLE, (size_t) -1
      call h5tcopy_f(H5T_NATIVE_CHARACTER, atype, e(1))
      e(2) = min(0, int(h5tset_size_variable(int(atype, c_int64_t), -1_c_size_t)))
      call h5tset_cset_f(atype, H5T_CSET_UTF8_F, e(3))
      call check(minval(e), 'h5tcopy_f/H5Tset_size/h5tset_cset_f('//name//')', io%path)
    end if
    call h5screate_f(H5S_SCALAR_F, space, hdferr)
    call check(hdferr, 'h5screate_f', io%path)
    call h5acreate_f(loc, name, atype, space, attr, hdferr)
    call check(hdferr, 'h5acreate_f('//name//')', io%path)
    if (present(r)) then
      call h5awrite_f(attr, atype, r, one, hdferr)
    else if (present(i)) then
      call h5awrite_f(attr, atype, i, one, hdferr)
    else
      text = s//c_null_char
      ptr = c_loc(text)
      call h5awrite_f(attr, atype, c_loc(ptr), hdferr)
    end if
    call check(hdferr, 'h5awrite_f('//name//')', io%path)
    call h5aclose_f(attr, e(1))
    call h5sclose_f(space, e(2))
    e(3) = 0
    if (.not. (present(r) .or. present(i))) call h5tclose_f(atype, e(3))
    call check(minval(e), 'h5aclose_f/h5sclose_f/h5tclose_f('//name//')', io%path)
  end subroutine put_attr

  !> Collective write of this rank's block (start, count) of dataset `dset` from `buf`, which
  !! holds product(count) values, first index fastest. An empty block takes part in the
  !! collective call with nothing selected.
  subroutine write_block(io, dset, start, count, buf, what)
    type(io_t), intent(in) :: io
    integer(hid_t), intent(in) :: dset
    integer(hsize_t), intent(in) :: start(:), count(:)
    real(wp), intent(in) :: buf(*)
    character(len=*), intent(in) :: what !! dataset path, for messages
    integer(hid_t) :: fspace, mspace
    integer(hsize_t) :: n
    integer :: hdferr, e(3)
    real(wp) :: empty(1)

    n = product(count)
    call h5dget_space_f(dset, fspace, hdferr)
    call check(hdferr, 'h5dget_space_f('//what//')', io%path)
    if (n > 0) then
      call h5sselect_hyperslab_f(fspace, H5S_SELECT_SET_F, start, count, hdferr)
      call check(hdferr, 'h5sselect_hyperslab_f('//what//')', io%path)
      call h5screate_simple_f(size(count), count, mspace, hdferr)
      call check(hdferr, 'h5screate_simple_f', io%path)
      call h5dwrite_f(dset, io%real_type, buf(1:n), [n], hdferr, mem_space_id=mspace, &
                      file_space_id=fspace, xfer_prp=io%dxpl)
    else
      empty = 0.0_wp
      call h5sselect_none_f(fspace, e(1))
      call h5screate_simple_f(1, one, mspace, e(2))
      call h5sselect_none_f(mspace, e(3))
      call check(minval(e), 'h5sselect_none_f('//what//')', io%path)
      call h5dwrite_f(dset, io%real_type, empty, one, hdferr, mem_space_id=mspace, &
                      file_space_id=fspace, xfer_prp=io%dxpl)
    end if
    call check(hdferr, 'h5dwrite_f('//what//')', io%path)
    call h5sclose_f(mspace, e(1))
    call h5sclose_f(fspace, e(2))
    call check(min(e(1), e(2)), 'h5sclose_f('//what//')', io%path)
  end subroutine write_block

end module dkt_run_file

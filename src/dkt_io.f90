!> Parallel HDF5 output of a run: one file `<dir>/<name>.h5` with the run metadata (/run), the
!> field snapshots (/fields/NNNNNN/<field>), small time series (/<group>/<name>, h5py shape
!> (n_samples,)), tables with one column per particle (/<group>/<name>, h5py shape (n_samples,
!> ncols)) and attributes on any group or dataset, plus the `<dir>/<name>.xdmf` sidecar (module
!> dkt_xdmf) that lets ParaView/VisIt open the fields, and its continuation when a run resumes
!> from a checkpoint (io_reopen). The checkpoint files are dkt_h5file's, which also holds the
!> HDF5 library open while any file is; every HDF5 call of dktlbm is in these I/O modules.
!> Every HDF5 return code is checked: in the run file a failed call stops the job
!> (fatal_local).
!>
!> The solver is decomposed in 1-D slabs along y: a rank holds global rows y0+1 .. y0+nyl of
!> every field, all nx columns, as a contiguous array (nx, nyl). Each rank writes its rows into a
!> hyperslab of a 2-D dataset of Fortran dims (nx, ny) (h5py: shape (ny, nx)) with one collective
!> transfer; a rank without rows takes part with an empty selection. Every procedure except
!> io_file_exists is collective over the communicator given to io_open, and every rank must pass
!> the same metadata (names, times, shapes); the field rows differ between ranks, and of series,
!> tables and attributes only rank 0's values are stored.
module dkt_io
  use iso_c_binding, only: c_null_char, c_ptr, c_loc, c_int, c_int64_t, c_size_t
  use iso_fortran_env, only: int16
  use dkt_kinds, only: wp, mpi_wp
  use dkt_errors, only: fatal_local
  use dkt_h5file, only: h5_library_open, h5_file_opened, h5_file_closed
  use dkt_xdmf, only: xdmf_t, xdmf_init, xdmf_add_frame, xdmf_write, xdmf_delete, xdmf_free
  use mpi_f08, only: MPI_Comm, MPI_INFO_NULL, MPI_IN_PLACE, MPI_LOGICAL, MPI_INTEGER, &
                     MPI_CHARACTER, MPI_LOR, MPI_SUM, MPI_MAX, MPI_MIN, MPI_Comm_rank, &
                     MPI_Bcast, MPI_Allreduce
  use hdf5, only: hid_t, hsize_t, size_t, h5kind_to_type, H5_REAL_KIND, &
                  H5_INTEGER_KIND, h5fcreate_f, h5fclose_f, h5fflush_f, H5F_ACC_EXCL_F, &
                  H5F_ACC_TRUNC_F, H5F_SCOPE_GLOBAL_F, h5pcreate_f, h5pclose_f, &
                  H5P_FILE_ACCESS_F, H5P_DATASET_XFER_F, H5P_DATASET_CREATE_F, &
                  h5pset_fapl_mpio_f, h5pset_dxpl_mpio_f, H5FD_MPIO_COLLECTIVE_F, h5eset_auto_f, &
                  h5pset_coll_metadata_write_f, h5pset_all_coll_metadata_ops_f, h5pset_chunk_f, &
                  h5gcreate_f, h5gclose_f, h5oopen_f, h5oclose_f, h5lexists_f, h5screate_f, &
                  h5screate_simple_f, h5sclose_f, h5sselect_hyperslab_f, h5sselect_none_f, &
                  h5sget_simple_extent_dims_f, h5sget_simple_extent_ndims_f, H5S_SCALAR_F, &
                  H5S_SELECT_SET_F, H5S_UNLIMITED_F, h5dcreate_f, h5dopen_f, h5dclose_f, &
                  h5dwrite_f, h5dget_space_f, h5dset_extent_f, h5acreate_f, h5awrite_f, &
                  h5aclose_f, h5aexists_f, h5adelete_f, h5tcopy_f, h5tset_size_f, &
                  h5tclose_f, H5T_NATIVE_CHARACTER, &
                  h5fopen_f, H5F_ACC_RDWR_F, h5gn_members_f, h5gget_obj_info_idx_f, &
                  H5G_DATASET_F, H5G_GROUP_F, h5ldelete_f, h5aopen_f, h5aread_f, &
                  H5F_ACC_RDONLY_F, h5dread_f, H5FD_MPIO_INDEPENDENT_F, h5pset_deflate_f, &
                  h5pset_shuffle_f, &
                  h5dget_type_f, h5tget_class_f, h5tget_size_f, H5T_INTEGER_F, &
                  h5tset_cset_f, H5T_CSET_UTF8_F
  implicit none
  private
  public :: io_t, io_open, io_write_run, io_write_fields, io_write_series, io_write_table, &
            io_write_attribute, io_close, io_flush, io_file_exists, io_reopen

  !> A plain HDF5 file of whole datasets (a checkpoint), written or read by all ranks of a
  !! communicator. The first failed call is remembered (`failed`); reads after it are skipped,

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

  !> Set attribute `name` of the group or dataset at `path` (e.g. '/particles' or
  !! '/particles/x') to rank 0's value: a real(wp), an integer or a character string (stored as
  !! given, trailing blanks included; h5py reads bytes). When nothing is at `path` yet, it is
  !! created as a group, with any missing group above it. An attribute of the same name is
  !! replaced. Collective. The rows held for series and tables are written first, so that an
  !! attribute can be set on such a dataset; the file is not flushed (io_write_fields, io_flush
  !! and io_close flush).
  interface io_write_attribute
    module procedure write_attribute_real, write_attribute_int, write_attribute_text
  end interface io_write_attribute

  integer(hsize_t), parameter :: one(1) = [1_hsize_t]
  !> the longest namelist text (characters) stored as the attribute /run namelist; a longer one
  !! (a scene of some 500 particles and more, up to megabytes) is the dataset /run/namelist
  integer, parameter :: NAMELIST_ATTR_MAX = 32768

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

  !> Create `<dir>/<name>.h5` for parallel writing. `dir` must exist. err is '' on success and
  !! otherwise the same message on every rank; nothing is created then.
  subroutine io_open(io, dir, name, comm, nx, ny, y0, nyl, dx, overwrite, err)
    type(io_t), intent(inout) :: io
    character(len=*), intent(in) :: dir  !! output directory (exists)
    character(len=*), intent(in) :: name !! file base name, e.g. the namelist basename
    type(MPI_Comm), intent(in) :: comm   !! the ranks that write; all call io_open
    integer, intent(in) :: nx, ny        !! global lattice size (columns, rows)
    integer, intent(in) :: y0, nyl       !! this rank holds global rows y0+1 .. y0+nyl
    real(wp), intent(in) :: dx           !! cm, lattice spacing (for the XDMF geometry)
    logical, intent(in) :: overwrite     !! replace an existing file
    character(len=:), allocatable, intent(out) :: err
    integer(hid_t) :: fapl
    integer :: hdferr, rows
    logical :: bad, any_bad, exists
    character(len=:), allocatable :: base

    err = ''
    if (io%is_open) call fatal_local('io_open: this io_t already holds the open file '''// &
                                     io%path//'''; call io_close first')
    call MPI_Comm_rank(comm, io%rank)
    base = trim(dir)
    if (len(base) > 1) then
      if (base(len(base):) == '/') base = base(:len(base) - 1)
    end if
    io%name = trim(name)
    io%path = base//'/'//io%name//'.h5'
    io%xdmf_path = base//'/'//io%name//'.xdmf'

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
    if (exists .and. .not. overwrite) then
      err = 'output file '''//io%path//''' exists; set output.overwrite = .true. '// &
            'or choose another output.dir'
      return
    end if

    call h5_library_open(hdferr)
    call check(hdferr, 'h5open_f', io%path)
    fapl = parallel_access(io, comm)
    ! A failed create is reported as err below (one message, not an HDF5 stack per rank).
    call h5eset_auto_f(0, hdferr)
    call check(hdferr, 'h5eset_auto_f', io%path)
    ! EXCL when the file should not exist, so a file that appeared meanwhile is not clobbered.
    if (exists) then
      call h5fcreate_f(io%path, H5F_ACC_TRUNC_F, io%file_id, hdferr, access_prp=fapl)
    else
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
      err = 'cannot create output file '''//io%path//'''; check that output.dir exists '// &
            'and is writable'
      return
    end if
    call h5_file_opened()

    call set_open(io, comm, nx, ny, y0, nyl, dx)

    ! A sidecar left by an earlier run would name groups this file does not have.
    if (io%rank == 0) call xdmf_delete(io%xdmf)
  end subroutine io_open

  !> Open the existing `<dir>/<name>.h5` of a run that resumes from a checkpoint at `step`, and
  !! cut it back to that step: the datasets of the series groups `groups` keep their first
  !! `samples` samples, their sub-groups (the episodes written at the end of a run) are removed,
  !! field groups of later steps are removed, and the XDMF sidecar is rebuilt from the field
  !! groups that remain. Arguments as io_open; err as io_open, also when a group marked
  !! `required` is missing or a dataset holds fewer than `samples` samples (a file not written
  !! up to the checkpoint: resumed, the run would lose them); the file is closed then.
  subroutine io_reopen(io, dir, name, comm, nx, ny, y0, nyl, dx, step, samples, groups, &
                       required, drop_at_step, field_order, err)
    type(io_t), intent(inout) :: io
    character(len=*), intent(in) :: dir, name
    type(MPI_Comm), intent(in) :: comm
    integer, intent(in) :: nx, ny, y0, nyl
    real(wp), intent(in) :: dx
    integer, intent(in) :: step           !! the checkpoint's step
    integer, intent(in) :: samples        !! series samples written up to that step
    character(len=*), intent(in) :: groups(:) !! series groups, e.g. 'particles'
    logical, intent(in) :: required(:)  !! groups(k) must be there when samples > 0
    logical, intent(in) :: drop_at_step   !! also remove the field group of `step` (it was the
                                          !! final output of a run, not a scheduled one)
    character(len=*), intent(in) :: field_order(:) !! the order the fields were written in
    character(len=:), allocatable, intent(out) :: err
    integer(hid_t) :: fapl
    integer :: hdferr, k
    logical :: bad, any_bad, exists
    logical, allocatable :: there(:)
    character(len=:), allocatable :: base

    err = ''
    call MPI_Comm_rank(comm, io%rank)
    base = trim(dir)
    io%name = trim(name)
    io%path = base//'/'//io%name//'.h5'
    io%xdmf_path = base//'/'//io%name//'.xdmf'
    if (io%rank == 0) exists = io_file_exists(io%path)
    call MPI_Bcast(exists, 1, MPI_LOGICAL, 0, comm)
    if (.not. exists) then
      err = 'the output file '''//io%path//''' of the run to resume is missing; a restart '// &
            'continues the output file of the run that wrote the checkpoint (same output.dir)'
      return
    end if
    call h5_library_open(hdferr)
    call check(hdferr, 'h5open_f', io%path)
    fapl = parallel_access(io, comm)
    ! a failed open is reported as err below (one message, not an HDF5 stack per rank)
    call h5eset_auto_f(0, hdferr)
    call check(hdferr, 'h5eset_auto_f', io%path)
    call h5fopen_f(io%path, H5F_ACC_RDWR_F, io%file_id, hdferr, access_prp=fapl)
    bad = hdferr < 0
    call h5eset_auto_f(1, hdferr)
    call check(hdferr, 'h5eset_auto_f', io%path)
    call h5pclose_f(fapl, hdferr)
    call check(hdferr, 'h5pclose_f(file access)', io%path)
    call MPI_Allreduce(bad, any_bad, 1, MPI_LOGICAL, MPI_LOR, comm)
    if (any_bad) then
      err = 'cannot open '''//io%path//''' to continue it'
      return
    end if
    call h5_file_opened()
    call set_open(io, comm, nx, ny, y0, nyl, dx)

    ! every group is checked before anything is cut, so that a refused file stays as it was
    allocate (there(size(groups)))
    do k = 1, size(groups)
      call h5lexists_f(io%file_id, trim(groups(k)), there(k), hdferr)
      call check(hdferr, 'h5lexists_f('//trim(groups(k))//')', io%path)
      if (there(k)) then
        call cut_group(trim(groups(k)), .false.)
      else if (required(k) .and. samples > 0 .and. len(err) == 0) then
        call short('has no /'//trim(groups(k)))
      end if
    end do
    if (len(err) > 0) then
      call io_close(io)
      return
    end if
    do k = 1, size(groups)
      if (there(k)) call cut_group(trim(groups(k)), .true.)
    end do
    call h5lexists_f(io%file_id, 'fields', exists, hdferr)
    call check(hdferr, 'h5lexists_f(fields)', io%path)
    if (exists) call cut_fields()
    call h5fflush_f(io%file_id, H5F_SCOPE_GLOBAL_F, hdferr)
    call check(hdferr, 'h5fflush_f', io%path)
    if (io%rank == 0) call xdmf_write(io%xdmf)
  contains
    !> err for a file that lacks samples the checkpoint counts: `what` it has instead.
    subroutine short(what)
      character(len=*), intent(in) :: what
      character(len=20) :: n
      write (n, '(i0)') samples
      err = 'the output file '''//io%path//''' '//what//', but the checkpoint counts '// &
            trim(n)//' samples: the file was not written up to the checkpoint''s step (a run '// &
            'killed before its file was flushed?), and resumed the run would lose them; resume '// &
            'with the file the checkpoint was written with, or run the scene again'
    end subroutine short

    !> The members of group `path`: names and kinds (H5G_DATASET_F, H5G_GROUP_F, ...).
    subroutine members(path, names, kinds)
      character(len=*), intent(in) :: path
      character(len=64), allocatable, intent(out) :: names(:)
      integer, allocatable, intent(out) :: kinds(:)
      integer :: n, j
      call h5gn_members_f(io%file_id, path, n, hdferr)
      call check(hdferr, 'h5gn_members_f('//path//')', io%path)
      allocate (names(n), kinds(n))
      do j = 1, n
        call h5gget_obj_info_idx_f(io%file_id, path, j - 1, names(j), kinds(j), hdferr)
        call check(hdferr, 'h5gget_obj_info_idx_f('//path//')', io%path)
      end do
    end subroutine members

    !> Check (cut = .false.) that every dataset of group `path` holds at least `samples`
    !! samples, setting err for the first that does not; or (cut = .true.) remove its
    !! sub-groups and cut its datasets to `samples` samples.
    subroutine cut_group(path, cut)
      character(len=*), intent(in) :: path
      logical, intent(in) :: cut
      character(len=64), allocatable :: names(:)
      integer, allocatable :: kinds(:)
      integer(hid_t) :: dset, space
      integer(hsize_t) :: dims(2), maxdims(2)
      integer :: j, nd
      character(len=20) :: held
      character(len=:), allocatable :: what
      call members(path, names, kinds)
      do j = 1, size(names)
        what = path//'/'//trim(names(j))
        if (kinds(j) == H5G_GROUP_F .and. cut) then
          call h5ldelete_f(io%file_id, what, hdferr)
          call check(hdferr, 'h5ldelete_f('//what//')', io%path)
        else if (kinds(j) == H5G_DATASET_F) then
          call h5dopen_f(io%file_id, what, dset, hdferr)
          call check(hdferr, 'h5dopen_f('//what//')', io%path)
          call h5dget_space_f(dset, space, hdferr)
          call check(hdferr, 'h5dget_space_f('//what//')', io%path)
          call h5sget_simple_extent_ndims_f(space, nd, hdferr)
          call check(hdferr, 'h5sget_simple_extent_ndims_f('//what//')', io%path)
          call h5sget_simple_extent_dims_f(space, dims(1:nd), maxdims(1:nd), hdferr)
          call check(min(hdferr, 0), 'h5sget_simple_extent_dims_f('//what//')', io%path)
          call h5sclose_f(space, hdferr)
          call check(hdferr, 'h5sclose_f', io%path)
          ! samples run along the last HDF5 dimension (write_rows)
          if (.not. cut .and. dims(nd) < samples .and. len(err) == 0) then
            write (held, '(i0)') dims(nd)
            call short('holds '//trim(held)//' samples of /'//what)
          else if (cut) then
            dims(nd) = samples
            call h5dset_extent_f(dset, dims(1:nd), hdferr)
            call check(hdferr, 'h5dset_extent_f('//what//')', io%path)
          end if
          call h5dclose_f(dset, hdferr)
          call check(hdferr, 'h5dclose_f('//what//')', io%path)
        end if
      end do
    end subroutine cut_group

    !> Remove the field groups after `step`; list the others in the sidecar, in step order.
    subroutine cut_fields()
      character(len=64), allocatable :: names(:), fnames(:)
      integer, allocatable :: kinds(:), fkinds(:), steps(:), bytes(:)
      real(wp) :: t, offset
      integer :: j, s, ios, m, np
      character(len=:), allocatable :: g
      call members('fields', names, kinds)
      allocate (steps(size(names)))
      do j = 1, size(names)
        read (names(j), *, iostat=ios) steps(j)
        if (ios /= 0) steps(j) = -1
      end do
      do j = 1, size(names)
        if (steps(j) > step .or. (drop_at_step .and. steps(j) == step)) then
          steps(j) = -1
          call h5ldelete_f(io%file_id, 'fields/'//trim(names(j)), hdferr)
          call check(hdferr, 'h5ldelete_f(fields/'//trim(names(j))//')', io%path)
        end if
      end do
      ! the names are zero-padded step numbers, so the listing is in step order
      do j = 1, size(names)
        s = steps(j)
        if (s < 0) cycle
        g = 'fields/'//trim(names(j))
        call read_attr(g, 'time', t)
        call read_attr(g, 'window_offset', offset)
        call members(g, fnames, fkinds)
        ! the fields are the datasets; a sub-group `particles` holds the disks (files written
        ! before version 0.2.0 have none)
        np = 0
        if (any(fkinds == H5G_GROUP_F .and. fnames == 'particles')) &
          np = dataset_length(g//'/particles/radius')
        fnames = ordered(pack(fnames, fkinds == H5G_DATASET_F))
        allocate (bytes(size(fnames)))
        do m = 1, size(fnames)
          bytes(m) = value_bytes(g//'/'//trim(fnames(m)))
        end do
        call xdmf_add_frame(io%xdmf, s, t, offset, field_group(s), fnames, bytes, np)
        deallocate (bytes)
      end do
    end subroutine cut_fields

    !> Bytes per value of dataset `path`, negative for an integer type (as xdmf_add_frame).
    integer function value_bytes(path) result(b)
      character(len=*), intent(in) :: path
      integer(hid_t) :: dset, dtype
      integer(size_t) :: size
      integer :: tclass
      call h5dopen_f(io%file_id, path, dset, hdferr)
      call check(hdferr, 'h5dopen_f('//path//')', io%path)
      call h5dget_type_f(dset, dtype, hdferr)
      call check(hdferr, 'h5dget_type_f('//path//')', io%path)
      call h5tget_class_f(dtype, tclass, hdferr)
      call check(hdferr, 'h5tget_class_f('//path//')', io%path)
      call h5tget_size_f(dtype, size, hdferr)
      call check(hdferr, 'h5tget_size_f('//path//')', io%path)
      b = int(size)
      if (tclass == H5T_INTEGER_F) b = -b
      call h5tclose_f(dtype, hdferr)
      call check(hdferr, 'h5tclose_f('//path//')', io%path)
      call h5dclose_f(dset, hdferr)
      call check(hdferr, 'h5dclose_f('//path//')', io%path)
    end function value_bytes

    !> Length of the 1-D dataset `path`.
    integer function dataset_length(path) result(n)
      character(len=*), intent(in) :: path
      integer(hid_t) :: dset, space
      integer(hsize_t) :: dims(1), maxdims(1)
      call h5dopen_f(io%file_id, path, dset, hdferr)
      call check(hdferr, 'h5dopen_f('//path//')', io%path)
      call h5dget_space_f(dset, space, hdferr)
      call check(hdferr, 'h5dget_space_f('//path//')', io%path)
      call h5sget_simple_extent_dims_f(space, dims, maxdims, hdferr)
      call check(min(hdferr, 0), 'h5sget_simple_extent_dims_f('//path//')', io%path)
      n = int(dims(1))
      call h5sclose_f(space, hdferr)
      call check(hdferr, 'h5sclose_f', io%path)
      call h5dclose_f(dset, hdferr)
      call check(hdferr, 'h5dclose_f('//path//')', io%path)
    end function dataset_length

    !> `found` in the order of field_order, names not in it last
    function ordered(found) result(out)
      character(len=64), intent(in) :: found(:)
      character(len=64) :: out(size(found))
      integer :: a, b, m
      m = 0
      do a = 1, size(field_order)
        do b = 1, size(found)
          if (trim(found(b)) == trim(field_order(a))) then
            m = m + 1
            out(m) = found(b)
          end if
        end do
      end do
      do b = 1, size(found)
        if (all(trim(found(b)) /= field_order)) then
          m = m + 1
          out(m) = found(b)
        end if
      end do
    end function ordered

    subroutine read_attr(path, aname, value)
      character(len=*), intent(in) :: path, aname
      real(wp), intent(out) :: value
      integer(hid_t) :: obj, attr
      call h5oopen_f(io%file_id, path, obj, hdferr)
      call check(hdferr, 'h5oopen_f('//path//')', io%path)
      call h5aopen_f(obj, aname, attr, hdferr)
      call check(hdferr, 'h5aopen_f('//path//' '//aname//')', io%path)
      call h5aread_f(attr, io%real_type, value, one, hdferr)
      call check(hdferr, 'h5aread_f('//path//' '//aname//')', io%path)
      call h5aclose_f(attr, hdferr)
      call check(hdferr, 'h5aclose_f('//path//' '//aname//')', io%path)
      call h5oclose_f(obj, hdferr)
      call check(hdferr, 'h5oclose_f('//path//')', io%path)
    end subroutine read_attr
  end subroutine io_reopen

  !> Write group /run: the configuration, provenance and one real attribute per lattice
  !! parameter with its unit. The configuration is the string attribute `namelist` when it
  !! has at most NAMELIST_ATTR_MAX characters, else the dataset /run/namelist (docs/output.md).
  !! Call once, with the same arguments on every rank.
  subroutine io_write_run(io, namelist_text, version, git_revision, nranks, compiler, flags, &
                          names, values, units)
    type(io_t), intent(inout) :: io
    character(len=*), intent(in) :: namelist_text !! the full configuration as namelist text
    character(len=*), intent(in) :: version       !! dktlbm version
    character(len=*), intent(in) :: git_revision  !! source revision of the build
    integer, intent(in) :: nranks                 !! MPI ranks of the run
    character(len=*), intent(in) :: compiler      !! compiler_version()
    character(len=*), intent(in) :: flags         !! compiler_options()
    character(len=*), intent(in) :: names(:)      !! lattice parameter names (dx, dt, tau, ...)
    real(wp), intent(in) :: values(:)             !! their values, in the units of dkt_config
    character(len=*), intent(in) :: units(:)      !! their units, stored as <name>_units
    integer(hid_t) :: grp
    integer :: hdferr, k

    call require_open(io, 'io_write_run')
    if (size(names) /= size(values) .or. size(names) /= size(units)) &
      call fatal_local('io_write_run: names, values and units differ in size')
    call h5gcreate_f(io%file_id, 'run', grp, hdferr)
    call check(hdferr, 'h5gcreate_f(/run)', io%path)
    if (len(namelist_text) <= NAMELIST_ATTR_MAX) then
      call put_attr(io, grp, 'namelist', s=namelist_text)
    else
      call put_text_dataset(io, grp, 'namelist', namelist_text)
    end if
    call put_attr(io, grp, 'version', s=version)
    call put_attr(io, grp, 'git_revision', s=git_revision)
    call put_attr(io, grp, 'ranks', i=nranks)
    call put_attr(io, grp, 'compiler', s=compiler)
    call put_attr(io, grp, 'compiler_flags', s=flags)
    do k = 1, size(names)
      call put_attr(io, grp, trim(names(k)), r=values(k))
      call put_attr(io, grp, trim(names(k))//'_units', s=trim(units(k)))
    end do
    call h5gclose_f(grp, hdferr)
    call check(hdferr, 'h5gclose_f(/run)', io%path)
    call h5fflush_f(io%file_id, H5F_SCOPE_GLOBAL_F, hdferr)
    call check(hdferr, 'h5fflush_f', io%path)
  end subroutine io_write_run

  !> Write one snapshot as group /fields/NNNNNN (one dataset per name, each with its `units`),
  !! flush the file and rewrite the XDMF sidecar, so a run that stops later still leaves
  !! readable output. With `solid`, the integer dataset `particle` (the particle number at each
  !! node, 0 in the fluid; int16 while the numbers fit, else int32). With `disks`, the sub-group
  !! `particles` holding rank 0's disks: position and velocity (h5py shape (n, 3), z = 0),
  !! radius, omega and id (1 .. n). Deflated when io%compress > 0. Collective.
  subroutine io_write_fields(io, step, t, offset, names, fields, units, solid, disks)
    type(io_t), intent(inout) :: io
    integer, intent(in) :: step             !! time step, >= 0, not written before
    real(wp), intent(in) :: t               !! s, simulated time
    real(wp), intent(in) :: offset          !! cm, y of the window bottom (0 for a fixed domain)
    character(len=*), intent(in) :: names(:) !! dataset names, e.g. 'rho', 'ux'
    real(wp), intent(in), contiguous, target :: fields(:, :, :) !! (nx, nyl, size(names))
    character(len=*), intent(in), optional :: units(:) !! unit of each field, e.g. 'cm/s'
    integer, intent(in), optional :: solid(:, :)     !! (nx, nyl): particle number, 0 = fluid
    !> (n, 6): x, y (cm), u, v (cm/s), omega (1/s), radius (cm) of each disk
    real(wp), intent(in), optional :: disks(:, :)
    integer(hid_t) :: grp
    integer(hsize_t) :: gdims(2), start(2), count(2)
    integer :: hdferr, k, np, nf, biggest
    integer, allocatable :: bytes(:)
    logical :: exists
    character(len=:), allocatable :: gname, unit
    character(len=64), allocatable :: listed(:)
    real(wp), target :: none(1)

    call require_open(io, 'io_write_fields')
    call flush_pending(io)
    if (size(fields, 1) /= io%nx .or. size(fields, 2) /= io%nyl .or. &
        size(fields, 3) /= size(names)) call fatal_local('io_write_fields: fields must have '// &
                                                         'shape (nx, nyl, size(names))')
    if (step < 0) call fatal_local('io_write_fields: step must be >= 0')
    gname = field_group(step)
    grp = open_object(io, 'fields') ! created with the first snapshot
    call h5oclose_f(grp, hdferr)
    call check(hdferr, 'h5oclose_f(/fields)', io%path)
    call h5lexists_f(io%file_id, gname, exists, hdferr)
    call check(hdferr, 'h5lexists_f('//gname//')', io%path)
    if (exists) call fatal_local('io_write_fields: '//gname//' is already in '''// &
                                 io%path//'''; each step is written once')
    call h5gcreate_f(io%file_id, gname, grp, hdferr)
    call check(hdferr, 'h5gcreate_f('//gname//')', io%path)
    call put_attr(io, grp, 'time', r=t)
    call put_attr(io, grp, 'time_units', s='s')
    call put_attr(io, grp, 'step', i=step)
    call put_attr(io, grp, 'window_offset', r=offset)
    call put_attr(io, grp, 'window_offset_units', s='cm')

    gdims = [integer(hsize_t) :: io%nx, io%ny]
    start = [integer(hsize_t) :: 0, io%y0]
    count = [integer(hsize_t) :: io%nx, io%nyl]
    nf = size(names)
    allocate (listed(nf + 1), bytes(nf + 1))
    do k = 1, nf
      listed(k) = names(k)
      bytes(k) = storage_size(1.0_wp)/8
      unit = ''
      if (present(units)) unit = trim(units(k))
      if (io%nyl > 0) then
        call put_dataset(io, grp, trim(names(k)), io%real_type, gdims, start, count, &
                         c_loc(fields(1, 1, k)), unit, chunked=.true.)
      else
        call put_dataset(io, grp, trim(names(k)), io%real_type, gdims, start, count, &
                         c_loc(none), unit, chunked=.true.)
      end if
    end do
    if (present(solid)) then
      nf = nf + 1
      listed(nf) = 'particle'
      if (size(solid, 1) /= io%nx .or. size(solid, 2) /= io%nyl) &
        call fatal_local('io_write_fields: solid must have shape (nx, nyl)')
      biggest = 0
      if (size(solid) > 0) biggest = maxval(solid)
      call MPI_Allreduce(MPI_IN_PLACE, biggest, 1, MPI_INTEGER, MPI_MAX, io%comm)
      if (biggest <= huge(1_int16)) then
        bytes(nf) = -2
        call put_solid(h5kind_to_type(int16, H5_INTEGER_KIND), .true.)
      else
        bytes(nf) = -(storage_size(1)/8)
        call put_solid(io%int_type, .false.)
      end if
    end if
    np = 0
    if (present(disks)) then
      np = size(disks, 1)
      if (size(disks, 2) /= 6) call fatal_local('io_write_fields: disks must have shape (n, 6)')
      if (np > 0) call put_disks()
    end if
    call h5gclose_f(grp, hdferr)
    call check(hdferr, 'h5gclose_f('//gname//')', io%path)
    call h5fflush_f(io%file_id, H5F_SCOPE_GLOBAL_F, hdferr)
    call check(hdferr, 'h5fflush_f', io%path)

    call xdmf_add_frame(io%xdmf, step, t, offset, gname, listed(1:nf), bytes(1:nf), np)
    if (io%rank == 0) call xdmf_write(io%xdmf)
  contains
    !> The particle numbers as int16 (`short`) or default integers, in a buffer of the type
    !! written, so that HDF5 converts nothing (a conversion would end collective writes).
    subroutine put_solid(htype, short)
      integer(hid_t), intent(in) :: htype
      logical, intent(in) :: short
      integer(int16), allocatable, target :: i2(:, :)
      integer, allocatable, target :: i4(:, :)
      if (short) then
        allocate (i2(io%nx, max(1, io%nyl)))
        i2 = 0_int16
        i2(:, 1:io%nyl) = int(solid, int16)
        call put_dataset(io, grp, 'particle', htype, gdims, start, count, c_loc(i2), '1', &
                         chunked=.true.)
      else
        allocate (i4(io%nx, max(1, io%nyl)))
        i4 = 0
        i4(:, 1:io%nyl) = solid
        call put_dataset(io, grp, 'particle', htype, gdims, start, count, c_loc(i4), '1', &
                         chunked=.true.)
      end if
    end subroutine put_solid

    !> The disks as rank 0 has them (the particle state is the same on every rank).
    subroutine put_disks()
      integer(hid_t) :: pgrp
      real(wp), allocatable, target :: xyz(:, :), uvw(:, :), col(:, :)
      integer, allocatable, target :: ids(:)
      integer(hsize_t) :: d2(2), d1(1), c2(2), c1(1), z2(2), z1(1)
      integer :: j
      allocate (xyz(3, np), uvw(3, np), col(np, 2), ids(np))
      xyz = 0.0_wp
      uvw = 0.0_wp
      xyz(1:2, :) = transpose(disks(:, 1:2))
      uvw(1:2, :) = transpose(disks(:, 3:4))
      col(:, 1) = disks(:, 6)
      col(:, 2) = disks(:, 5)
      ids = [(j, j=1, np)]
      d2 = [integer(hsize_t) :: 3, np]
      d1 = [integer(hsize_t) :: np]
      z2 = 0
      z1 = 0
      c2 = merge(d2, z2, io%rank == 0)
      c1 = merge(d1, z1, io%rank == 0)
      call h5gcreate_f(grp, 'particles', pgrp, hdferr)
      call check(hdferr, 'h5gcreate_f('//gname//'/particles)', io%path)
      call put_dataset(io, pgrp, 'position', io%real_type, d2, z2, c2, c_loc(xyz), 'cm', &
                       chunked=.false.)
      call put_dataset(io, pgrp, 'velocity', io%real_type, d2, z2, c2, c_loc(uvw), 'cm/s', &
                       chunked=.false.)
      call put_dataset(io, pgrp, 'radius', io%real_type, d1, z1, c1, c_loc(col(1, 1)), 'cm', &
                       chunked=.false.)
      call put_dataset(io, pgrp, 'omega', io%real_type, d1, z1, c1, c_loc(col(1, 2)), '1/s', &
                       chunked=.false.)
      call put_dataset(io, pgrp, 'id', io%int_type, d1, z1, c1, c_loc(ids), '1', chunked=.false.)
      call h5gclose_f(pgrp, hdferr)
      call check(hdferr, 'h5gclose_f('//gname//'/particles)', io%path)
    end subroutine put_disks
  end subroutine io_write_fields

  !> Append one row to the extendible 1-D datasets /<group>/<names(k)> (h5py shape
  !! (n_samples,)), created on first use, with the group. The values of rank 0 are written; the
  !! other ranks pass an array of the same size. Collective. The row is held in memory until
  !! io_flush, io_write_fields or io_close writes it (or the held rows fill their store).
  !! `units` (one per name) become the datasets' attribute `units` when they are created.
  subroutine io_write_series(io, group, names, values, units)
    type(io_t), intent(inout) :: io
    character(len=*), intent(in) :: group    !! group path under /, e.g. 'diagnostics'
    character(len=*), intent(in) :: names(:) !! one dataset per name
    real(wp), intent(in) :: values(:)        !! the new row (rank 0's values are kept)
    character(len=*), intent(in), optional :: units(:) !! e.g. 's', 'cm'

    call require_open(io, 'io_write_series')
    if (size(names) /= size(values)) call fatal_local('io_write_series: names and values '// &
                                                      'differ in size')
    call hold_rows(io, group, names, reshape(values, [1, size(values)]), 1, 'io_write_series', &
                   units)
  end subroutine io_write_series

  !> Append one sample to the extendible 2-D datasets /<group>/<names(k)>, created on first use
  !! with the group: h5py sees shape (n_samples, ncols), one column per particle, where
  !! values(:, k) is the new row of names(k). The column count is fixed when a dataset is
  !! created. The values of rank 0 are written; the other ranks pass an array of the same
  !! shape. A group may hold series and tables side by side (/particles/t and /particles/x).
  !! Collective; held in memory like io_write_series, with `units` as there.
  subroutine io_write_table(io, group, names, values, units)
    type(io_t), intent(inout) :: io
    character(len=*), intent(in) :: group    !! group path under /, e.g. 'particles'
    character(len=*), intent(in) :: names(:) !! one dataset per name, e.g. 'x', 'y', 'omega'
    real(wp), intent(in) :: values(:, :)     !! (ncols, size(names)), rank 0's are kept
    character(len=*), intent(in), optional :: units(:) !! e.g. 'cm', 'cm/s'
    integer :: ext(4)

    call require_open(io, 'io_write_table')
    if (size(values, 2) /= size(names) .or. size(values, 1) < 1) &
      call fatal_local('io_write_table: values must have shape (ncols, size(names)), ncols >= 1')
    ! The dataset shapes are collective metadata: a rank with another shape would corrupt them.
    ! Compared across the ranks when the datasets are first held; after that each rank holds
    ! its rows at that shape and refuses another (hold_rows).
    if (find_pending(io, group, names(1)) == 0) then
      call MPI_Allreduce([shape(values), -shape(values)], ext, 4, MPI_INTEGER, MPI_MAX, io%comm)
      if (any(ext(1:2) /= -ext(3:4))) call fatal_local('io_write_table: the ranks pass '// &
                                                       'values of different shapes for '// &
                                                       trim(group))
    end if
    call hold_rows(io, group, names, values, 2, 'io_write_table', units)
  end subroutine io_write_table

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

  subroutine write_attribute_real(io, path, name, value)
    type(io_t), intent(inout) :: io
    character(len=*), intent(in) :: path !! group or dataset, e.g. '/diagnostics'
    character(len=*), intent(in) :: name !! attribute name
    real(wp), intent(in) :: value        !! rank 0's value is stored
    real(wp) :: v

    call require_open(io, 'io_write_attribute')
    v = value
    call MPI_Bcast(v, 1, mpi_wp, 0, io%comm)
    call set_attribute(io, path, name, r=v)
  end subroutine write_attribute_real

  subroutine write_attribute_int(io, path, name, value)
    type(io_t), intent(inout) :: io
    character(len=*), intent(in) :: path !! group or dataset, e.g. '/particles'
    character(len=*), intent(in) :: name !! attribute name
    integer, intent(in) :: value         !! rank 0's value is stored
    integer :: v

    call require_open(io, 'io_write_attribute')
    v = value
    call MPI_Bcast(v, 1, MPI_INTEGER, 0, io%comm)
    call set_attribute(io, path, name, i=v)
  end subroutine write_attribute_int

  subroutine write_attribute_text(io, path, name, value)
    type(io_t), intent(inout) :: io
    character(len=*), intent(in) :: path  !! group or dataset, e.g. '/diagnostics'
    character(len=*), intent(in) :: name  !! attribute name
    character(len=*), intent(in) :: value !! rank 0's value is stored
    character(len=:), allocatable :: v
    integer :: n

    call require_open(io, 'io_write_attribute')
    ! The length first: the other ranks' strings may be longer or shorter than rank 0's.
    n = len(value)
    call MPI_Bcast(n, 1, MPI_INTEGER, 0, io%comm)
    allocate (character(len=n) :: v)
    if (io%rank == 0) v = value
    call MPI_Bcast(v, n, MPI_CHARACTER, 0, io%comm)
    call set_attribute(io, path, name, s=v)
  end subroutine write_attribute_text

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

  ! ---------------------------------------------------------------------------------------------

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

  !> Write attribute `name` (one of r, i, s present) of the object at `path`, created as a group
  !! if missing, replacing an attribute of that name. The held rows are written first, so that
  !! a dataset held so far (e.g. /particles/x) is in the file and not made a group.
  subroutine set_attribute(io, path, name, r, i, s)
    type(io_t), intent(inout) :: io
    character(len=*), intent(in) :: path, name
    real(wp), intent(in), optional :: r
    integer, intent(in), optional :: i
    character(len=*), intent(in), optional :: s
    integer(hid_t) :: obj
    integer :: hdferr
    logical :: exists

    if (len_trim(name) == 0) call fatal_local('io_write_attribute: empty attribute name for '''// &
                                              trim(path)//'''')
    call flush_pending(io)
    obj = open_object(io, path)
    call h5aexists_f(obj, trim(name), exists, hdferr)
    call check(hdferr, 'h5aexists_f('//trim(path)//' '//trim(name)//')', io%path)
    if (exists) then
      call h5adelete_f(obj, trim(name), hdferr)
      call check(hdferr, 'h5adelete_f('//trim(path)//' '//trim(name)//')', io%path)
    end if
    call put_attr(io, obj, trim(name), r, i, s)
    call h5oclose_f(obj, hdferr)
    call check(hdferr, 'h5oclose_f('//trim(path)//')', io%path)
  end subroutine set_attribute

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

  !> The string dataset `name` in `loc`: one fixed-length UTF-8 string holding `text`, written
  !! by rank 0 (the text is the same on every rank). Collective.
  subroutine put_text_dataset(io, loc, name, text)
    type(io_t), intent(in) :: io
    integer(hid_t), intent(in) :: loc
    character(len=*), intent(in) :: name, text
    character(len=:), allocatable, target :: buf
    type(c_ptr) :: ptr
    integer(hid_t) :: stype
    integer :: e(3)
    buf = text
    call h5tcopy_f(H5T_NATIVE_CHARACTER, stype, e(1))
    call h5tset_size_f(stype, int(max(1, len(buf)), size_t), e(2))
    call h5tset_cset_f(stype, H5T_CSET_UTF8_F, e(3))
    call check(minval(e), 'h5tcopy_f/h5tset_size_f/h5tset_cset_f('//name//')', io%path)
    ! the address is taken first: gfortran 12 passes len(buf) as the length of the next
    ! character argument when c_loc(buf) of a deferred-length string is an actual argument
    ptr = c_loc(buf)
    call put_dataset(io, loc, name, stype, one, [0_hsize_t], &
                     merge(one, [0_hsize_t], io%rank == 0), ptr, '', chunked=.false.)
    call h5tclose_f(stype, e(1))
    call check(e(1), 'h5tclose_f('//name//')', io%path)
  end subroutine put_text_dataset

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

  !> Create dataset `name` of type `htype` and dimensions `dims` (Fortran order) in `loc`, with
  !! the string attribute `units` unless that is '', and write this rank's block (start, count)
  !! from `buf` (product(count) values of type `htype`, first index fastest) collectively; an
  !! empty block takes part with nothing selected. A `chunked` dataset is shuffled and
  !! deflated at level io%compress when that is > 0 (parallel HDF5 writes filtered datasets
  !! collectively only, as here).
  subroutine put_dataset(io, loc, name, htype, dims, start, count, buf, units, chunked)
    type(io_t), intent(in) :: io
    integer(hid_t), intent(in) :: loc, htype
    character(len=*), intent(in) :: name, units
    integer(hsize_t), intent(in) :: dims(:), start(:), count(:)
    type(c_ptr), intent(in) :: buf
    logical, intent(in) :: chunked
    integer(hid_t) :: fspace, mspace, dcpl, dset
    integer(hsize_t) :: chunk(size(dims)), last
    integer :: hdferr, e(3)
    real(wp), target :: empty(1)

    call h5pcreate_f(H5P_DATASET_CREATE_F, dcpl, hdferr)
    call check(hdferr, 'h5pcreate_f(dataset create)', io%path)
    if (chunked .and. io%compress > 0) then
      ! whole rows, about 64 Ki values a chunk: large enough to compress well, small enough
      ! that the ranks share the work of a snapshot
      last = dims(size(dims))
      chunk = dims
      chunk(size(dims)) = max(1_hsize_t, min(last, 65536_hsize_t/max(1_hsize_t, dims(1))))
      call h5pset_chunk_f(dcpl, size(dims), chunk, e(1))
      ! byte shuffle first: it groups the sign and exponent bytes of the reals, which deflate
      ! then packs; the mantissa bytes of a flow field barely compress (docs/output.md)
      call h5pset_shuffle_f(dcpl, e(2))
      call h5pset_deflate_f(dcpl, io%compress, e(3))
      call check(minval(e), 'h5pset_chunk_f/h5pset_shuffle_f/h5pset_deflate_f('//name//')', &
                 io%path)
    end if
    call h5screate_simple_f(size(dims), dims, fspace, hdferr)
    call check(hdferr, 'h5screate_simple_f', io%path)
    call h5dcreate_f(loc, name, htype, fspace, dset, hdferr, dcpl_id=dcpl)
    call check(hdferr, 'h5dcreate_f('//name//')', io%path)
    call h5pclose_f(dcpl, hdferr)
    call check(hdferr, 'h5pclose_f(dataset create)', io%path)
    if (product(count) > 0) then
      call h5sselect_hyperslab_f(fspace, H5S_SELECT_SET_F, start, count, hdferr)
      call check(hdferr, 'h5sselect_hyperslab_f('//name//')', io%path)
      call h5screate_simple_f(size(count), count, mspace, hdferr)
      call check(hdferr, 'h5screate_simple_f', io%path)
      call h5dwrite_f(dset, htype, buf, hdferr, mem_space_id=mspace, file_space_id=fspace, &
                      xfer_prp=io%dxpl)
    else
      call h5sselect_none_f(fspace, e(1))
      call h5screate_simple_f(1, one, mspace, e(2))
      call h5sselect_none_f(mspace, e(3))
      call check(minval(e), 'h5sselect_none_f('//name//')', io%path)
      call h5dwrite_f(dset, htype, c_loc(empty), hdferr, mem_space_id=mspace, &
                      file_space_id=fspace, xfer_prp=io%dxpl)
    end if
    call check(hdferr, 'h5dwrite_f('//name//')', io%path)
    call h5sclose_f(mspace, e(1))
    call h5sclose_f(fspace, e(2))
    call check(min(e(1), e(2)), 'h5sclose_f('//name//')', io%path)
    if (len(units) > 0) call put_attr(io, dset, 'units', s=units)
    call h5dclose_f(dset, hdferr)
    call check(hdferr, 'h5dclose_f('//name//')', io%path)
  end subroutine put_dataset

end module dkt_io

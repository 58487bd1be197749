!> Parallel HDF5 output of a run: one file `<dir>/<name>.h5` with the run metadata (/run), the
!> field snapshots (/fields/NNNNNN/<field>) and small time series (/<group>/<name>), plus the
!> `<dir>/<name>.xdmf` sidecar that lets ParaView/VisIt open the fields. All HDF5 of dktlbm lives
!> here; every HDF5 return code is checked.
!>
!> The solver is decomposed in 1-D slabs along y: a rank holds global rows y0+1 .. y0+nyl of
!> every field, all nx columns, as a contiguous array (nx, nyl). Each rank writes its rows into a
!> hyperslab of a 2-D dataset of Fortran dims (nx, ny) (h5py: shape (ny, nx)) with one collective
!> transfer; a rank without rows takes part with an empty selection. Every procedure except
!> io_file_exists is collective over the communicator given to io_open, and every rank must pass
!> the same metadata (names, times, attributes); only the field rows differ between ranks.
module dkt_io
  use iso_c_binding, only: c_char, c_int, c_null_char
  use dkt_kinds, only: wp
  use dkt_errors, only: fatal_local
  use mpi_f08, only: MPI_Comm, MPI_INFO_NULL, MPI_LOGICAL, MPI_INTEGER, MPI_LOR, MPI_SUM, &
                     MPI_Comm_rank, MPI_Bcast, MPI_Allreduce
  use hdf5, only: hid_t, hsize_t, size_t, h5open_f, h5close_f, h5kind_to_type, H5_REAL_KIND, &
                  H5_INTEGER_KIND, h5fcreate_f, h5fclose_f, h5fflush_f, H5F_ACC_EXCL_F, &
                  H5F_ACC_TRUNC_F, H5F_SCOPE_GLOBAL_F, h5pcreate_f, h5pclose_f, &
                  H5P_FILE_ACCESS_F, H5P_DATASET_XFER_F, H5P_DATASET_CREATE_F, &
                  h5pset_fapl_mpio_f, h5pset_dxpl_mpio_f, H5FD_MPIO_COLLECTIVE_F, h5eset_auto_f, &
                  h5pset_coll_metadata_write_f, h5pset_all_coll_metadata_ops_f, h5pset_chunk_f, &
                  h5gcreate_f, h5gopen_f, h5gclose_f, h5lexists_f, h5screate_f, &
                  h5screate_simple_f, h5sclose_f, h5sselect_hyperslab_f, h5sselect_none_f, &
                  h5sget_simple_extent_dims_f, H5S_SCALAR_F, H5S_SELECT_SET_F, H5S_UNLIMITED_F, &
                  h5dcreate_f, h5dopen_f, h5dclose_f, h5dwrite_f, h5dget_space_f, &
                  h5dset_extent_f, h5acreate_f, h5awrite_f, h5aclose_f, h5tcopy_f, h5tset_size_f, &
                  h5tset_strpad_f, h5tclose_f, H5T_NATIVE_CHARACTER, H5T_STR_NULLPAD_F
  implicit none
  private
  public :: io_t, io_open, io_write_run, io_write_fields, io_write_series, io_close, &
            io_file_exists

  !> One field snapshot already in the file, remembered for the XDMF sidecar.
  type :: frame_t
    integer :: step = 0
    real(wp) :: t = 0.0_wp      !! s
    real(wp) :: offset = 0.0_wp !! cm, window offset along y
    character(len=:), allocatable :: fields(:) !! dataset names in /fields/NNNNNN
  end type frame_t

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
    character(len=:), allocatable :: name      !! file base name, no extension
    character(len=:), allocatable :: path      !! <dir>/<name>.h5
    character(len=:), allocatable :: xdmf_path !! <dir>/<name>.xdmf
    integer :: nframes = 0
    type(frame_t), allocatable :: frames(:)
  end type io_t

  !> Files open through io_open in this process. The HDF5 library is process-global state: it is
  !> opened with the first file and closed with the last, so that closing one io_t never
  !> invalidates the identifiers of another (h5close_f closes every open object).
  integer :: n_open_files = 0

  integer(hsize_t), parameter :: one(1) = [1_hsize_t]

  interface
    function c_rename(old, new) bind(c, name='rename') result(status)
      import :: c_char, c_int
      character(kind=c_char), intent(in) :: old(*), new(*)
      integer(c_int) :: status
    end function c_rename
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

    if (n_open_files == 0) then
      call h5open_f(hdferr)
      call check(hdferr, 'h5open_f', io%path)
    end if
    call h5pcreate_f(H5P_FILE_ACCESS_F, fapl, hdferr)
    call check(hdferr, 'h5pcreate_f(file access)', io%path)
    call h5pset_fapl_mpio_f(fapl, comm%MPI_VAL, MPI_INFO_NULL%MPI_VAL, hdferr)
    call check(hdferr, 'h5pset_fapl_mpio_f', io%path)
    ! Metadata written and read collectively: one rank does the I/O instead of all of them.
    call h5pset_coll_metadata_write_f(fapl, .true., hdferr)
    call check(hdferr, 'h5pset_coll_metadata_write_f', io%path)
    call h5pset_all_coll_metadata_ops_f(fapl, .true., hdferr)
    call check(hdferr, 'h5pset_all_coll_metadata_ops_f', io%path)
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
    n_open_files = n_open_files + 1

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
    io%nframes = 0
    if (allocated(io%frames)) deallocate (io%frames)
    allocate (io%frames(8))
    io%is_open = .true.

    ! A sidecar left by an earlier run would name groups this file does not have.
    if (io%rank == 0) call delete_file(io%xdmf_path)
  end subroutine io_open

  !> Write group /run: the configuration, provenance and one real attribute per lattice
  !! parameter. Call once, with the same arguments on every rank.
  subroutine io_write_run(io, namelist_text, version, git_revision, nranks, compiler, flags, &
                          names, values)
    type(io_t), intent(inout) :: io
    character(len=*), intent(in) :: namelist_text !! the full configuration as namelist text
    character(len=*), intent(in) :: version       !! dktlbm version
    character(len=*), intent(in) :: git_revision  !! source revision of the build
    integer, intent(in) :: nranks                 !! MPI ranks of the run
    character(len=*), intent(in) :: compiler      !! compiler_version()
    character(len=*), intent(in) :: flags         !! compiler_options()
    character(len=*), intent(in) :: names(:)      !! lattice parameter names (dx, dt, tau, ...)
    real(wp), intent(in) :: values(:)             !! their values, in the units of dkt_config
    integer(hid_t) :: grp
    integer :: hdferr, k

    call require_open(io, 'io_write_run')
    if (size(names) /= size(values)) call fatal_local('io_write_run: names and values differ '// &
                                                      'in size')
    call h5gcreate_f(io%file_id, 'run', grp, hdferr)
    call check(hdferr, 'h5gcreate_f(/run)', io%path)
    call put_string_attr(grp, 'namelist', namelist_text, io%path)
    call put_string_attr(grp, 'version', version, io%path)
    call put_string_attr(grp, 'git_revision', git_revision, io%path)
    call put_int_attr(grp, 'ranks', nranks, io%int_type, io%path)
    call put_string_attr(grp, 'compiler', compiler, io%path)
    call put_string_attr(grp, 'compiler_flags', flags, io%path)
    do k = 1, size(names)
      call put_real_attr(grp, trim(names(k)), values(k), io%real_type, io%path)
    end do
    call h5gclose_f(grp, hdferr)
    call check(hdferr, 'h5gclose_f(/run)', io%path)
    call h5fflush_f(io%file_id, H5F_SCOPE_GLOBAL_F, hdferr)
    call check(hdferr, 'h5fflush_f', io%path)
  end subroutine io_write_run

  !> Write one snapshot as group /fields/NNNNNN (one dataset per name), flush the file and
  !! rewrite the XDMF sidecar, so a run that stops later still leaves readable output.
  subroutine io_write_fields(io, step, t, offset, names, fields)
    type(io_t), intent(inout) :: io
    integer, intent(in) :: step             !! time step, >= 0, not written before
    real(wp), intent(in) :: t               !! s, simulated time
    real(wp), intent(in) :: offset          !! cm, y of the window bottom (0 for a fixed domain)
    character(len=*), intent(in) :: names(:) !! dataset names, e.g. 'rho', 'ux'
    real(wp), intent(in), contiguous :: fields(:, :, :) !! (nx, nyl, size(names)), this slab
    integer(hid_t) :: grp, fspace, dset
    integer(hsize_t) :: gdims(2), start(2), count(2)
    integer :: hdferr, k
    logical :: exists
    character(len=:), allocatable :: gname

    call require_open(io, 'io_write_fields')
    if (size(fields, 1) /= io%nx .or. size(fields, 2) /= io%nyl .or. &
        size(fields, 3) /= size(names)) call fatal_local('io_write_fields: fields must have '// &
                                                         'shape (nx, nyl, size(names))')
    if (step < 0) call fatal_local('io_write_fields: step must be >= 0')
    gname = field_group(step)
    call h5lexists_f(io%file_id, 'fields', exists, hdferr)
    call check(hdferr, 'h5lexists_f(/fields)', io%path)
    if (.not. exists) then
      call h5gcreate_f(io%file_id, 'fields', grp, hdferr)
      call check(hdferr, 'h5gcreate_f(/fields)', io%path)
      call h5gclose_f(grp, hdferr)
      call check(hdferr, 'h5gclose_f(/fields)', io%path)
    else
      call h5lexists_f(io%file_id, gname, exists, hdferr)
      call check(hdferr, 'h5lexists_f('//gname//')', io%path)
      if (exists) call fatal_local('io_write_fields: '//gname//' is already in '''// &
                                   io%path//'''; each step is written once')
    end if
    call h5gcreate_f(io%file_id, gname, grp, hdferr)
    call check(hdferr, 'h5gcreate_f('//gname//')', io%path)
    call put_real_attr(grp, 'time', t, io%real_type, io%path)
    call put_int_attr(grp, 'step', step, io%int_type, io%path)
    call put_real_attr(grp, 'window_offset', offset, io%real_type, io%path)

    gdims = [integer(hsize_t) :: io%nx, io%ny]
    start = [integer(hsize_t) :: 0, io%y0]
    count = [integer(hsize_t) :: io%nx, io%nyl]
    do k = 1, size(names)
      call h5screate_simple_f(2, gdims, fspace, hdferr)
      call check(hdferr, 'h5screate_simple_f', io%path)
      call h5dcreate_f(grp, trim(names(k)), io%real_type, fspace, dset, hdferr)
      call check(hdferr, 'h5dcreate_f('//gname//'/'//trim(names(k))//')', io%path)
      call h5sclose_f(fspace, hdferr)
      call check(hdferr, 'h5sclose_f', io%path)
      call write_block(io, dset, start, count, fields(:, :, k), gname//'/'//trim(names(k)))
      call h5dclose_f(dset, hdferr)
      call check(hdferr, 'h5dclose_f', io%path)
    end do
    call h5gclose_f(grp, hdferr)
    call check(hdferr, 'h5gclose_f('//gname//')', io%path)
    call h5fflush_f(io%file_id, H5F_SCOPE_GLOBAL_F, hdferr)
    call check(hdferr, 'h5fflush_f', io%path)

    call add_frame(io, step, t, offset, names)
    if (io%rank == 0) call write_xdmf(io)
  end subroutine io_write_fields

  !> Append one row to the extendible 1-D datasets /<group>/<names(k)>, created on first use.
  !! The values of rank 0 are written; the other ranks pass an array of the same size. `group`
  !! is one level below the root (e.g. 'diagnostics'). Not flushed: io_write_fields and io_close
  !! flush.
  subroutine io_write_series(io, group, names, values)
    type(io_t), intent(inout) :: io
    character(len=*), intent(in) :: group    !! group name under /, one level
    character(len=*), intent(in) :: names(:) !! one dataset per name
    real(wp), intent(in) :: values(:)        !! the new row (rank 0's values are kept)
    integer(hid_t) :: grp, dcpl, fspace, dset
    integer(hsize_t) :: dims(1), maxdims(1)
    integer(hsize_t), parameter :: chunk(1) = [1024_hsize_t]
    integer :: hdferr, k
    logical :: exists

    call require_open(io, 'io_write_series')
    if (size(names) /= size(values)) call fatal_local('io_write_series: names and values '// &
                                                      'differ in size')
    call h5lexists_f(io%file_id, trim(group), exists, hdferr)
    call check(hdferr, 'h5lexists_f(/'//trim(group)//')', io%path)
    if (exists) then
      call h5gopen_f(io%file_id, trim(group), grp, hdferr)
    else
      call h5gcreate_f(io%file_id, trim(group), grp, hdferr)
    end if
    call check(hdferr, 'h5gcreate_f/h5gopen_f(/'//trim(group)//')', io%path)
    do k = 1, size(names)
      call h5lexists_f(grp, trim(names(k)), exists, hdferr)
      call check(hdferr, 'h5lexists_f', io%path)
      if (exists) then
        call h5dopen_f(grp, trim(names(k)), dset, hdferr)
        call check(hdferr, 'h5dopen_f('//trim(names(k))//')', io%path)
      else
        ! Extendible datasets must be chunked; one chunk holds many rows.
        call h5screate_simple_f(1, [0_hsize_t], fspace, hdferr, maxdims=[H5S_UNLIMITED_F])
        call check(hdferr, 'h5screate_simple_f', io%path)
        call h5pcreate_f(H5P_DATASET_CREATE_F, dcpl, hdferr)
        call check(hdferr, 'h5pcreate_f(dataset create)', io%path)
        call h5pset_chunk_f(dcpl, 1, chunk, hdferr)
        call check(hdferr, 'h5pset_chunk_f', io%path)
        call h5dcreate_f(grp, trim(names(k)), io%real_type, fspace, dset, hdferr, dcpl_id=dcpl)
        call check(hdferr, 'h5dcreate_f('//trim(names(k))//')', io%path)
        call h5pclose_f(dcpl, hdferr)
        call check(hdferr, 'h5pclose_f', io%path)
        call h5sclose_f(fspace, hdferr)
        call check(hdferr, 'h5sclose_f', io%path)
      end if
      call h5dget_space_f(dset, fspace, hdferr)
      call check(hdferr, 'h5dget_space_f', io%path)
      call h5sget_simple_extent_dims_f(fspace, dims, maxdims, hdferr)
      call check(min(hdferr, 0), 'h5sget_simple_extent_dims_f', io%path)
      call h5sclose_f(fspace, hdferr)
      call check(hdferr, 'h5sclose_f', io%path)
      call h5dset_extent_f(dset, dims + 1, hdferr)
      call check(hdferr, 'h5dset_extent_f('//trim(names(k))//')', io%path)
      ! Rank 0 writes the new row; the others join the collective write with nothing.
      call write_block(io, dset, dims, merge(one, [0_hsize_t], io%rank == 0), values(k:k), &
                       trim(group)//'/'//trim(names(k)))
      call h5dclose_f(dset, hdferr)
      call check(hdferr, 'h5dclose_f', io%path)
    end do
    call h5gclose_f(grp, hdferr)
    call check(hdferr, 'h5gclose_f(/'//trim(group)//')', io%path)
  end subroutine io_write_series

  !> Flush and close the file; the last file closed also closes the HDF5 library.
  subroutine io_close(io)
    type(io_t), intent(inout) :: io
    integer :: hdferr

    if (.not. io%is_open) return
    call h5fflush_f(io%file_id, H5F_SCOPE_GLOBAL_F, hdferr)
    call check(hdferr, 'h5fflush_f', io%path)
    call h5pclose_f(io%dxpl, hdferr)
    call check(hdferr, 'h5pclose_f(transfer)', io%path)
    call h5fclose_f(io%file_id, hdferr)
    call check(hdferr, 'h5fclose_f', io%path)
    n_open_files = n_open_files - 1
    if (n_open_files == 0) then
      call h5close_f(hdferr)
      call check(hdferr, 'h5close_f', io%path)
    end if
    io%is_open = .false.
    io%file_id = -1
    io%dxpl = -1
    io%nframes = 0
    if (allocated(io%frames)) deallocate (io%frames)
  end subroutine io_close

  !> Whether a file exists at `path` (local to the calling rank).
  logical function io_file_exists(path)
    character(len=*), intent(in) :: path
    inquire (file=path, exist=io_file_exists)
  end function io_file_exists

  ! ---------------------------------------------------------------------------------------------

  !> Group of the fields of `step`: six digits, more when the step needs them.
  function field_group(step) result(gname)
    integer, intent(in) :: step
    character(len=:), allocatable :: gname
    character(len=24) :: digits
    write (digits, '(i6.6)') step
    if (step > 999999) write (digits, '(i0)') step
    gname = '/fields/'//trim(digits)
  end function field_group

  subroutine add_frame(io, step, t, offset, names)
    type(io_t), intent(inout) :: io
    integer, intent(in) :: step
    real(wp), intent(in) :: t, offset
    character(len=*), intent(in) :: names(:)
    type(frame_t), allocatable :: grown(:)
    integer :: k

    if (io%nframes == size(io%frames)) then
      allocate (grown(2*size(io%frames)))
      grown(1:io%nframes) = io%frames(1:io%nframes)
      call move_alloc(grown, io%frames)
    end if
    io%nframes = io%nframes + 1
    associate (f => io%frames(io%nframes))
      f%step = step
      f%t = t
      f%offset = offset
      allocate (character(len=max(1, maxval(len_trim(names)))) :: f%fields(size(names)))
      do k = 1, size(names)
        f%fields(k) = trim(names(k))
      end do
    end associate
  end subroutine add_frame

  !> Rewrite the XDMF sidecar (rank 0) with every snapshot so far: a temporal collection of
  !! 2DCoRectMesh grids on the cell-centred nodes ((i - 1/2) dx, (j - 1/2) dx + offset). XDMF
  !! lists dimensions, origin and spacing slowest index first, i.e. (y, x). Written to a
  !! temporary name and renamed, so a reader never sees a half-written file.
  subroutine write_xdmf(io)
    type(io_t), intent(in) :: io
    character(len=:), allocatable :: xml, dims, tmp, prec
    character(len=512) :: msg
    character(len=1), parameter :: nl = new_line('a')
    integer :: u, ios, n, k

    dims = itoa(io%ny)//' '//itoa(io%nx)
    prec = itoa(storage_size(1.0_wp)/8)
    xml = '<?xml version="1.0" ?>'//nl//'<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>'//nl// &
          '<Xdmf Version="3.0">'//nl//'  <Domain>'//nl// &
          '    <Grid Name="fields" GridType="Collection" CollectionType="Temporal">'//nl
    do n = 1, io%nframes
      associate (f => io%frames(n))
        xml = xml//'      <Grid Name="step '//itoa(f%step)//'" GridType="Uniform">'//nl// &
              '        <Time Value="'//rtoa(f%t)//'"/>'//nl// &
              '        <Topology TopologyType="2DCoRectMesh" Dimensions="'//dims//'"/>'//nl// &
              '        <Geometry GeometryType="ORIGIN_DXDY">'//nl// &
              '          <DataItem Name="Origin" Dimensions="2" NumberType="Float" '// &
              'Precision="'//prec//'" Format="XML">'//rtoa(0.5_wp*io%dx + f%offset)//' '// &
              rtoa(0.5_wp*io%dx)//'</DataItem>'//nl// &
              '          <DataItem Name="Spacing" Dimensions="2" NumberType="Float" '// &
              'Precision="'//prec//'" Format="XML">'//rtoa(io%dx)//' '//rtoa(io%dx)// &
              '</DataItem>'//nl//'        </Geometry>'//nl
        do k = 1, size(f%fields)
          xml = xml//'        <Attribute Name="'//xml_escape(trim(f%fields(k)))// &
                '" AttributeType="Scalar" Center="Node">'//nl// &
                '          <DataItem Dimensions="'//dims//'" NumberType="Float" Precision="'// &
                prec//'" Format="HDF">'//xml_escape(io%name//'.h5:'//field_group(f%step)// &
                                                    '/'//trim(f%fields(k)))//'</DataItem>'//nl// &
                '        </Attribute>'//nl
        end do
        xml = xml//'      </Grid>'//nl
      end associate
    end do
    xml = xml//'    </Grid>'//nl//'  </Domain>'//nl//'</Xdmf>'

    tmp = io%xdmf_path//'.tmp'
    open (newunit=u, file=tmp, status='replace', action='write', form='formatted', &
          iostat=ios, iomsg=msg)
    if (ios == 0) write (u, '(a)', iostat=ios, iomsg=msg) xml
    if (ios == 0) close (u, iostat=ios, iomsg=msg)
    if (ios /= 0) call fatal_local('cannot write '''//tmp//''': '//trim(msg))
    if (c_rename(tmp//c_null_char, io%xdmf_path//c_null_char) /= 0) &
      call fatal_local('cannot rename '''//tmp//''' to '''//io%xdmf_path//'''')
  end subroutine write_xdmf

  subroutine delete_file(path)
    character(len=*), intent(in) :: path
    integer :: u, ios
    if (.not. io_file_exists(path)) return
    open (newunit=u, file=path, status='old', iostat=ios)
    if (ios == 0) close (u, status='delete', iostat=ios)
    if (ios /= 0) call fatal_local('cannot remove the stale file '''//path//'''')
  end subroutine delete_file

  pure function xml_escape(s) result(r)
    character(len=*), intent(in) :: s
    character(len=:), allocatable :: r
    integer :: i
    r = ''
    do i = 1, len(s)
      select case (s(i:i))
      case ('&'); r = r//'&amp;'
      case ('<'); r = r//'&lt;'
      case ('>'); r = r//'&gt;'
      case ('"'); r = r//'&quot;'
      case default; r = r//s(i:i)
      end select
    end do
  end function xml_escape

  pure function itoa(i) result(s)
    integer, intent(in) :: i
    character(len=:), allocatable :: s
    character(len=24) :: buf
    write (buf, '(i0)') i
    s = trim(buf)
  end function itoa

  !> Shortest-safe text of a real: 17 significant digits read back to the same value.
  pure function rtoa(x) result(s)
    real(wp), intent(in) :: x
    character(len=:), allocatable :: s
    character(len=32) :: buf
    write (buf, '(es24.16e3)') x
    s = trim(adjustl(buf))
  end function rtoa

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

  subroutine put_string_attr(loc, name, value, path)
    integer(hid_t), intent(in) :: loc
    character(len=*), intent(in) :: name, value, path
    integer(hid_t) :: stype, attr
    integer :: hdferr

    ! A fixed-length, null-padded string; an empty one is stored as a single NUL (h5py: b'').
    call h5tcopy_f(H5T_NATIVE_CHARACTER, stype, hdferr)
    call check(hdferr, 'h5tcopy_f', path)
    call h5tset_size_f(stype, int(max(1, len(value)), size_t), hdferr)
    call check(hdferr, 'h5tset_size_f', path)
    call h5tset_strpad_f(stype, H5T_STR_NULLPAD_F, hdferr)
    call check(hdferr, 'h5tset_strpad_f', path)
    attr = new_attr(loc, name, stype, path)
    if (len(value) > 0) then
      call h5awrite_f(attr, stype, value, one, hdferr)
    else
      call h5awrite_f(attr, stype, c_null_char, one, hdferr)
    end if
    call end_attr(attr, hdferr, name, path)
    call h5tclose_f(stype, hdferr)
    call check(hdferr, 'h5tclose_f', path)
  end subroutine put_string_attr

  subroutine put_real_attr(loc, name, value, rtype, path)
    integer(hid_t), intent(in) :: loc, rtype
    character(len=*), intent(in) :: name, path
    real(wp), intent(in) :: value
    integer(hid_t) :: attr
    integer :: hdferr

    attr = new_attr(loc, name, rtype, path)
    call h5awrite_f(attr, rtype, value, one, hdferr)
    call end_attr(attr, hdferr, name, path)
  end subroutine put_real_attr

  subroutine put_int_attr(loc, name, value, itype, path)
    integer(hid_t), intent(in) :: loc, itype
    character(len=*), intent(in) :: name, path
    integer, intent(in) :: value
    integer(hid_t) :: attr
    integer :: hdferr

    attr = new_attr(loc, name, itype, path)
    call h5awrite_f(attr, itype, value, one, hdferr)
    call end_attr(attr, hdferr, name, path)
  end subroutine put_int_attr

  !> A new scalar attribute `name` of type `atype` on object `loc`.
  function new_attr(loc, name, atype, path) result(attr)
    integer(hid_t), intent(in) :: loc, atype
    character(len=*), intent(in) :: name, path
    integer(hid_t) :: attr, space
    integer :: hdferr

    call h5screate_f(H5S_SCALAR_F, space, hdferr)
    call check(hdferr, 'h5screate_f', path)
    call h5acreate_f(loc, name, atype, space, attr, hdferr)
    call check(hdferr, 'h5acreate_f('//name//')', path)
    call h5sclose_f(space, hdferr)
    call check(hdferr, 'h5sclose_f', path)
  end function new_attr

  !> Check the write of attribute `name` (return code `werr`) and close it.
  subroutine end_attr(attr, werr, name, path)
    integer(hid_t), intent(in) :: attr
    integer, intent(in) :: werr
    character(len=*), intent(in) :: name, path
    integer :: hdferr

    call check(werr, 'h5awrite_f('//name//')', path)
    call h5aclose_f(attr, hdferr)
    call check(hdferr, 'h5aclose_f('//name//')', path)
  end subroutine end_attr

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

end module dkt_io

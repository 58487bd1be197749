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
  use iso_c_binding, only: c_ptr, c_loc
  use iso_fortran_env, only: int16
  use dkt_kinds, only: wp, mpi_wp
  use dkt_errors, only: fatal_local
  use dkt_xdmf, only: xdmf_add_frame, xdmf_write, xdmf_delete
  use mpi_f08, only: MPI_Comm, MPI_IN_PLACE, MPI_INTEGER, MPI_CHARACTER, MPI_MAX, MPI_Bcast, &
                     MPI_Allreduce
  use hdf5, only: hid_t, hsize_t, size_t, h5kind_to_type, H5_INTEGER_KIND, h5fflush_f, &
                  H5F_SCOPE_GLOBAL_F, h5pcreate_f, h5pclose_f, H5P_DATASET_CREATE_F, &
                  h5pset_chunk_f, h5gcreate_f, h5gclose_f, h5oclose_f, h5lexists_f, &
                  h5screate_simple_f, h5sclose_f, h5sselect_hyperslab_f, h5sselect_none_f, &
                  H5S_SELECT_SET_F, h5dcreate_f, h5dclose_f, h5dwrite_f, &
                  h5tcopy_f, h5tset_size_f, h5tclose_f, H5T_NATIVE_CHARACTER, &
                  h5pset_deflate_f, h5pset_shuffle_f, h5tset_cset_f, H5T_CSET_UTF8_F
  use dkt_run_file, only: io_t, io_close, io_flush, io_file_exists, run_file_open, require_open, &
                          check, field_group, find_pending, hold_rows, flush_pending, &
                          open_object, put_attr, one, delete_attribute
  use dkt_io_reopen, only: io_reopen, io_read_series, io_run_id
  implicit none
  private
  public :: io_t, io_open, io_write_run, io_write_fields, io_write_series, io_write_table, &
            io_write_attribute, io_close, io_flush, io_file_exists, io_reopen, io_set_rows, &
            io_read_series, io_run_id

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

  !> the longest namelist text (characters) stored as the attribute /run namelist; a longer one
  !! (a scene of some 500 particles and more, up to megabytes) is the dataset /run/namelist
  integer, parameter :: NAMELIST_ATTR_MAX = 32768

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
    character(len=:), allocatable :: base

    err = ''
    if (io%is_open) call fatal_local('io_open: this io_t already holds the open file '''// &
                                     io%path//'''; call io_close first')
    base = trim(dir)
    if (len(base) > 1) then
      if (base(len(base):) == '/') base = base(:len(base) - 1)
    end if
    call run_file_open(io, base, name, comm, nx, ny, y0, nyl, dx, .false., overwrite, err)
    if (len(err) > 0) return

    ! A sidecar left by an earlier run would name groups this file does not have.
    if (io%rank == 0) call xdmf_delete(io%xdmf)
  end subroutine io_open

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

  !> The lattice the next snapshots have: ny rows, this rank's y0+1 .. y0+nyl (a window that
  !! grows, docs/model.md §5, writes snapshots of more rows than the first; each snapshot's
  !! datasets and XDMF grid have the rows it was written with).
  subroutine io_set_rows(io, ny, y0, nyl)
    type(io_t), intent(inout) :: io
    integer, intent(in) :: ny, y0, nyl
    io%ny = ny
    io%y0 = y0
    io%nyl = nyl
  end subroutine io_set_rows

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
        call put_solid(io, grp, gdims, start, count, solid, &
                       h5kind_to_type(int16, H5_INTEGER_KIND), .true.)
      else
        bytes(nf) = -(storage_size(1)/8)
        call put_solid(io, grp, gdims, start, count, solid, io%int_type, .false.)
      end if
    end if
    np = 0
    if (present(disks)) then
      np = size(disks, 1)
      if (size(disks, 2) /= 6) call fatal_local('io_write_fields: disks must have shape (n, 6)')
      if (np > 0) call put_disks(io, grp, gname, disks)
    end if
    call h5gclose_f(grp, hdferr)
    call check(hdferr, 'h5gclose_f('//gname//')', io%path)
    call h5fflush_f(io%file_id, H5F_SCOPE_GLOBAL_F, hdferr)
    call check(hdferr, 'h5fflush_f', io%path)

    call xdmf_add_frame(io%xdmf, step, t, offset, gname, listed(1:nf), bytes(1:nf), np, io%ny)
    if (io%rank == 0) call xdmf_write(io%xdmf)
  end subroutine io_write_fields

  !> The particle numbers as int16 (`short`) or default integers, in a buffer of the type
  !! written, so that HDF5 converts nothing (a conversion would end collective writes).
  subroutine put_solid(io, grp, gdims, start, count, solid, htype, short)
    type(io_t), intent(in) :: io
    integer(hid_t), intent(in) :: grp                 !! the snapshot's group
    integer(hsize_t), intent(in) :: gdims(2), start(2), count(2) !! the fields' hyperslab
    integer, intent(in) :: solid(:, :)                !! (nx, nyl): particle number, 0 = fluid
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
  subroutine put_disks(io, grp, gname, disks)
    type(io_t), intent(in) :: io
    integer(hid_t), intent(in) :: grp          !! the snapshot's group
    character(len=*), intent(in) :: gname      !! its path, for messages
    real(wp), intent(in) :: disks(:, :)        !! (n, 6) as io_write_fields
    integer(hid_t) :: pgrp
    real(wp), allocatable, target :: xyz(:, :), uvw(:, :), col(:, :)
    integer, allocatable, target :: ids(:)
    integer(hsize_t) :: d2(2), d1(1), c2(2), c1(1), z2(2), z1(1)
    integer :: j, np, hdferr
    np = size(disks, 1)
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

    if (len_trim(name) == 0) call fatal_local('io_write_attribute: empty attribute name for '''// &
                                              trim(path)//'''')
    call flush_pending(io)
    obj = open_object(io, path)
    call delete_attribute(io, obj, trim(path), trim(name))
    call put_attr(io, obj, trim(name), r, i, s)
    call h5oclose_f(obj, hdferr)
    call check(hdferr, 'h5oclose_f('//trim(path)//')', io%path)
  end subroutine set_attribute

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

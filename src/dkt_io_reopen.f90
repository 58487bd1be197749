!> The restart side of the run file: a run that resumes from a checkpoint continues the output
!> file of the run that wrote it, cut back to the checkpoint's step (io_reopen). The file is
!> checked before anything is cut, so that a refused file stays as it was. Collective over the
!> communicator given to io_reopen.
module dkt_io_reopen
  use dkt_kinds, only: wp
  use dkt_run_file, only: io_t, io_close, run_file_open, check, field_group, one, open_object, &
                          delete_attribute
  use dkt_xdmf, only: xdmf_add_frame, xdmf_write
  use dkt_h5file, only: h5_real_attribute
  use mpi_f08, only: MPI_Comm
  use hdf5, only: hid_t, hsize_t, size_t, h5fflush_f, H5F_SCOPE_GLOBAL_F, h5lexists_f, &
                  h5gn_members_f, h5gget_obj_info_idx_f, H5G_DATASET_F, H5G_GROUP_F, &
                  h5ldelete_f, h5dopen_f, h5dclose_f, h5dget_space_f, h5dset_extent_f, &
                  h5dget_type_f, h5dread_f, h5sclose_f, h5sget_simple_extent_dims_f, &
                  h5sget_simple_extent_ndims_f, h5tget_class_f, h5tget_size_f, h5tclose_f, &
                  H5T_INTEGER_F, h5oclose_f
  implicit none
  private
  public :: io_reopen, io_read_series, io_run_id

  !> the attributes of /diagnostics that say a run finished (dkt_output output_pair_report):
  !! a continued run removes them until it finishes in its turn
  character(len=12), parameter :: FINAL_REPORT(4) = &
                                  [character(len=12) :: 'pattern', 'episodes', 'open_episode', &
                                                         'ended_early']

contains

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
    integer :: hdferr, k
    logical :: exists
    logical, allocatable :: there(:)

    call run_file_open(io, dir, name, comm, nx, ny, y0, nyl, dx, .true., .false., err)
    if (len(err) > 0) return
    ! every group is checked before anything is cut, so that a refused file stays as it was
    allocate (there(size(groups)))
    do k = 1, size(groups)
      call h5lexists_f(io%file_id, trim(groups(k)), there(k), hdferr)
      call check(hdferr, 'h5lexists_f('//trim(groups(k))//')', io%path)
      if (there(k)) then
        call cut_group(io, trim(groups(k)), samples, .false., err)
      else if (required(k) .and. samples > 0 .and. len(err) == 0) then
        err = short_of(io, samples, 'has no /'//trim(groups(k)))
      end if
    end do
    if (len(err) > 0) then
      call io_close(io)
      return
    end if
    do k = 1, size(groups)
      if (there(k)) call cut_group(io, trim(groups(k)), samples, .true., err)
    end do
    call h5lexists_f(io%file_id, 'fields', exists, hdferr)
    call check(hdferr, 'h5lexists_f(fields)', io%path)
    if (exists) call cut_fields(io, step, drop_at_step, field_order)
    ! the report of a finished run is written again when the continued run finishes; until
    ! then it would describe a run that is not over (a run killed while extended)
    if (there(findloc(groups, 'diagnostics', 1))) then
      do k = 1, size(FINAL_REPORT)
        call drop_attribute(io, 'diagnostics', trim(FINAL_REPORT(k)))
      end do
    end if
    call h5fflush_f(io%file_id, H5F_SCOPE_GLOBAL_F, hdferr)
    call check(hdferr, 'h5fflush_f', io%path)
    if (io%rank == 0) call xdmf_write(io%xdmf)
  end subroutine io_reopen

  !> Remove the attribute `aname` of the group at `path`, if it is there.
  subroutine drop_attribute(io, path, aname)
    type(io_t), intent(in) :: io
    character(len=*), intent(in) :: path, aname
    integer(hid_t) :: obj
    integer :: hdferr
    obj = open_object(io, path)
    call delete_attribute(io, obj, path, aname)
    call h5oclose_f(obj, hdferr)
    call check(hdferr, 'h5oclose_f('//path//')', io%path)
  end subroutine drop_attribute

  !> The refusal of a file that lacks samples the checkpoint counts: `what` it has instead.
  function short_of(io, samples, what) result(err)
    type(io_t), intent(in) :: io
    integer, intent(in) :: samples !! series samples the checkpoint counts
    character(len=*), intent(in) :: what
    character(len=:), allocatable :: err
    character(len=20) :: n
    write (n, '(i0)') samples
    err = 'the output file '''//io%path//''' '//what//', but the checkpoint counts '// &
          trim(n)//' samples: the file was not written up to the checkpoint''s step (a run '// &
          'killed before its file was flushed?), and resumed the run would lose them; resume '// &
          'with the file the checkpoint was written with, or run the scene again'
  end function short_of

  !> The members of group `path`: names and kinds (H5G_DATASET_F, H5G_GROUP_F, ...).
  subroutine members(io, path, names, kinds)
    type(io_t), intent(in) :: io
    character(len=*), intent(in) :: path
    character(len=64), allocatable, intent(out) :: names(:)
    integer, allocatable, intent(out) :: kinds(:)
    integer :: n, j, hdferr
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
  subroutine cut_group(io, path, samples, cut, err)
    type(io_t), intent(in) :: io
    character(len=*), intent(in) :: path
    integer, intent(in) :: samples !! series samples the checkpoint counts
    logical, intent(in) :: cut
    character(len=:), allocatable, intent(inout) :: err
    character(len=64), allocatable :: names(:)
    integer, allocatable :: kinds(:)
    integer(hid_t) :: dset
    integer(hsize_t) :: dims(2)
    integer :: j, nd, hdferr
    character(len=20) :: held
    character(len=:), allocatable :: what
    call members(io, path, names, kinds)
    do j = 1, size(names)
      what = path//'/'//trim(names(j))
      if (kinds(j) == H5G_GROUP_F .and. cut) then
        call h5ldelete_f(io%file_id, what, hdferr)
        call check(hdferr, 'h5ldelete_f('//what//')', io%path)
      else if (kinds(j) == H5G_DATASET_F) then
        call h5dopen_f(io%file_id, what, dset, hdferr)
        call check(hdferr, 'h5dopen_f('//what//')', io%path)
        call extent(io, dset, what, nd, dims)
        ! samples run along the last HDF5 dimension (write_rows)
        if (.not. cut .and. dims(nd) < samples .and. len(err) == 0) then
          write (held, '(i0)') dims(nd)
          err = short_of(io, samples, 'holds '//trim(held)//' samples of /'//what)
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
  subroutine cut_fields(io, step, drop_at_step, field_order)
    type(io_t), intent(inout) :: io
    integer, intent(in) :: step              !! the checkpoint's step
    logical, intent(in) :: drop_at_step      !! also remove the field group of `step`
    character(len=*), intent(in) :: field_order(:) !! the order the fields were written in
    character(len=64), allocatable :: names(:), fnames(:)
    integer, allocatable :: kinds(:), fkinds(:), steps(:), bytes(:)
    real(wp) :: t, offset
    integer :: j, s, ios, m, np, hdferr
    character(len=:), allocatable :: g
    call members(io, 'fields', names, kinds)
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
      call read_attr(io, g, 'time', t)
      call read_attr(io, g, 'window_offset', offset)
      call members(io, g, fnames, fkinds)
      ! the fields are the datasets; a sub-group `particles` holds the disks (files written
      ! before version 0.2.0 have none)
      np = 0
      if (any(fkinds == H5G_GROUP_F .and. fnames == 'particles')) &
        np = dataset_length(io, g//'/particles/radius')
      fnames = ordered(pack(fnames, fkinds == H5G_DATASET_F), field_order)
      allocate (bytes(size(fnames)))
      do m = 1, size(fnames)
        bytes(m) = value_bytes(io, g//'/'//trim(fnames(m)))
      end do
      ! a window that grows writes later snapshots with more rows (docs/model.md §5)
      call xdmf_add_frame(io%xdmf, s, t, offset, field_group(s), fnames, bytes, np, &
                          field_rows(io, g//'/'//trim(fnames(1))))
      deallocate (bytes)
    end do
  end subroutine cut_fields

  !> Bytes per value of dataset `path`, negative for an integer type (as xdmf_add_frame).
  integer function value_bytes(io, path) result(b)
    type(io_t), intent(in) :: io
    character(len=*), intent(in) :: path
    integer(hid_t) :: dset, dtype
    integer(size_t) :: size
    integer :: tclass, hdferr
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

  !> Rows (h5py's first extent) of the 2-D field dataset `path`.
  integer function field_rows(io, path) result(n)
    type(io_t), intent(in) :: io
    character(len=*), intent(in) :: path
    integer(hsize_t) :: dims(2)
    integer :: nd
    call dataset_extent(io, path, nd, dims)
    n = io%ny
    if (nd == 2) n = int(dims(2))
  end function field_rows

  !> The identity of the open run file (/run run_id), 0 when it has none (an earlier version's).
  real(wp) function io_run_id(io) result(id)
    type(io_t), intent(in) :: io
    logical :: found
    call h5_real_attribute(io%file_id, 'run', 'run_id', id, found)
    if (.not. found) id = 0.0_wp
  end function io_run_id

  !> Every value of the real series dataset `path` of the open run file: values(w, s) is value
  !! w of sample s (w = 1 for a 1-D series, the particle or column of a 2-D one). Every rank
  !! reads it (independently); a restart rebuilds the CSV file from it.
  subroutine io_read_series(io, path, values)
    type(io_t), intent(in) :: io
    character(len=*), intent(in) :: path
    real(wp), allocatable, intent(out) :: values(:, :)
    integer(hid_t) :: dset
    integer(hsize_t) :: dims(2), shp(2)
    integer :: nd, hdferr
    call h5dopen_f(io%file_id, path, dset, hdferr)
    call check(hdferr, 'h5dopen_f('//path//')', io%path)
    call extent(io, dset, path, nd, dims)
    shp = [1_hsize_t, dims(1)]
    if (nd == 2) shp = dims
    allocate (values(shp(1), shp(2)))
    if (size(values) > 0) then
      call h5dread_f(dset, io%real_type, values, shp, hdferr)
      call check(hdferr, 'h5dread_f('//path//')', io%path)
    end if
    call h5dclose_f(dset, hdferr)
    call check(hdferr, 'h5dclose_f('//path//')', io%path)
  end subroutine io_read_series

  !> Length of the 1-D dataset `path`.
  integer function dataset_length(io, path) result(n)
    type(io_t), intent(in) :: io
    character(len=*), intent(in) :: path
    integer(hsize_t) :: dims(2)
    integer :: nd
    call dataset_extent(io, path, nd, dims)
    n = int(dims(1))
  end function dataset_length

  !> The rank `nd` and extents `dims` of the dataset `path` (opened and closed here).
  subroutine dataset_extent(io, path, nd, dims)
    type(io_t), intent(in) :: io
    character(len=*), intent(in) :: path
    integer, intent(out) :: nd
    integer(hsize_t), intent(out) :: dims(2)
    integer(hid_t) :: dset
    integer :: hdferr
    call h5dopen_f(io%file_id, path, dset, hdferr)
    call check(hdferr, 'h5dopen_f('//path//')', io%path)
    call extent(io, dset, path, nd, dims)
    call h5dclose_f(dset, hdferr)
    call check(hdferr, 'h5dclose_f('//path//')', io%path)
  end subroutine dataset_extent

  !> The rank `nd` (1 or 2) and dimensions of the open dataset `dset` at `what`.
  subroutine extent(io, dset, what, nd, dims)
    type(io_t), intent(in) :: io
    integer(hid_t), intent(in) :: dset
    character(len=*), intent(in) :: what
    integer, intent(out) :: nd
    integer(hsize_t), intent(out) :: dims(2)
    integer(hid_t) :: space
    integer(hsize_t) :: maxdims(2)
    integer :: hdferr
    call h5dget_space_f(dset, space, hdferr)
    call check(hdferr, 'h5dget_space_f('//what//')', io%path)
    call h5sget_simple_extent_ndims_f(space, nd, hdferr)
    call check(hdferr, 'h5sget_simple_extent_ndims_f('//what//')', io%path)
    call h5sget_simple_extent_dims_f(space, dims(1:nd), maxdims(1:nd), hdferr)
    call check(min(hdferr, 0), 'h5sget_simple_extent_dims_f('//what//')', io%path)
    call h5sclose_f(space, hdferr)
    call check(hdferr, 'h5sclose_f', io%path)
  end subroutine extent

  !> `found` in the order of field_order, names not in it last
  function ordered(found, field_order) result(out)
    character(len=64), intent(in) :: found(:)
    character(len=*), intent(in) :: field_order(:)
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

  !> The real attribute `aname` of the object at `path` (h5_real_attribute); a missing or
  !! unreadable one stops the run as every failed call here does.
  subroutine read_attr(io, path, aname, value)
    type(io_t), intent(in) :: io
    character(len=*), intent(in) :: path, aname
    real(wp), intent(out) :: value
    logical :: found
    call h5_real_attribute(io%file_id, path, aname, value, found)
    if (.not. found) call check(-1, 'h5aread_f('//path//' '//aname//')', io%path)
  end subroutine read_attr

end module dkt_io_reopen

!> The XDMF sidecar `<dir>/<name>.xdmf` of an output file: the field snapshots written so far and
!> the XML that lets ParaView/VisIt open them as a time series on the lattice. Text only: the
!> HDF5 itself is written by dkt_io, which keeps an xdmf_t per open file. Every rank may record
!> frames; one rank (rank 0) writes the file.
module dkt_xdmf
  use dkt_kinds, only: wp
  use dkt_filesystem, only: rename_file
  use dkt_registry, only: itoa
  use dkt_errors, only: fatal_local
  implicit none
  private
  public :: xdmf_t, xdmf_init, xdmf_add_frame, xdmf_write, xdmf_delete, xdmf_free

  !> One field snapshot already in the HDF5 file.
  type :: frame_t
    integer :: step = 0
    real(wp) :: t = 0.0_wp      !! s
    real(wp) :: offset = 0.0_wp !! cm, window offset along y
    character(len=:), allocatable :: group     !! HDF5 group of the snapshot, e.g. /fields/000010
    !> dataset names in that group; fixed length, because gfortran 12 loses the length of a
    !! deferred-length character array when the frames are copied into a grown array
    character(len=64), allocatable :: fields(:)
  end type frame_t

  !> The sidecar of one HDF5 file and the snapshots it lists.
  type :: xdmf_t
    character(len=:), allocatable :: path    !! <dir>/<name>.xdmf
    character(len=:), allocatable :: h5_name !! the HDF5 file, in the same directory
    integer :: nx = 0 !! global columns
    integer :: ny = 0 !! global rows
    real(wp) :: dx = 0.0_wp !! cm, lattice spacing
    integer :: nframes = 0
    type(frame_t), allocatable :: frames(:)
  end type xdmf_t

contains

  !> Start an empty sidecar for the (nx, ny) lattice of spacing dx stored in `h5_name`. Nothing
  !! is written to disk.
  subroutine xdmf_init(x, path, h5_name, nx, ny, dx)
    type(xdmf_t), intent(inout) :: x
    character(len=*), intent(in) :: path    !! <dir>/<name>.xdmf
    character(len=*), intent(in) :: h5_name !! HDF5 file name relative to the sidecar
    integer, intent(in) :: nx, ny           !! global lattice size (columns, rows)
    real(wp), intent(in) :: dx              !! cm, lattice spacing

    x%path = path
    x%h5_name = h5_name
    x%nx = nx
    x%ny = ny
    x%dx = dx
    x%nframes = 0
    if (allocated(x%frames)) deallocate (x%frames)
    allocate (x%frames(8))
  end subroutine xdmf_init

  !> Record the snapshot of `step` stored as datasets `names` in HDF5 group `group`.
  subroutine xdmf_add_frame(x, step, t, offset, group, names)
    type(xdmf_t), intent(inout) :: x
    integer, intent(in) :: step              !! time step
    real(wp), intent(in) :: t                !! s, simulated time
    real(wp), intent(in) :: offset           !! cm, y of the window bottom
    character(len=*), intent(in) :: group    !! absolute HDF5 path of the snapshot group
    character(len=*), intent(in) :: names(:) !! its datasets, one per field
    type(frame_t), allocatable :: grown(:)
    integer :: k

    if (x%nframes == size(x%frames)) then
      allocate (grown(2*size(x%frames)))
      grown(1:x%nframes) = x%frames(1:x%nframes)
      call move_alloc(grown, x%frames)
    end if
    x%nframes = x%nframes + 1
    associate (f => x%frames(x%nframes))
      f%step = step
      f%t = t
      f%offset = offset
      f%group = group
      if (maxval(len_trim(names)) > len(f%fields)) &
        call fatal_local('xdmf_add_frame: a field name is longer than 64 characters')
      allocate (f%fields(size(names)))
      do k = 1, size(names)
        f%fields(k) = trim(names(k))
      end do
    end associate
  end subroutine xdmf_add_frame

  !> Rewrite the sidecar with every snapshot so far: a temporal collection of 2DCoRectMesh grids
  !! on the cell-centred nodes ((i - 1/2) dx, (j - 1/2) dx + offset). XDMF lists dimensions,
  !! origin and spacing slowest index first, i.e. (y, x). Written to a temporary name and
  !! renamed, so a reader never sees a half-written file.
  subroutine xdmf_write(x)
    type(xdmf_t), intent(in) :: x
    character(len=:), allocatable :: xml, dims, tmp, prec
    character(len=512) :: msg
    character(len=1), parameter :: nl = new_line('a')
    integer :: u, ios, n, k

    dims = itoa(x%ny)//' '//itoa(x%nx)
    prec = itoa(storage_size(1.0_wp)/8)
    xml = '<?xml version="1.0" ?>'//nl//'<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>'//nl// &
          '<Xdmf Version="3.0">'//nl//'  <Domain>'//nl// &
          '    <Grid Name="fields" GridType="Collection" CollectionType="Temporal">'//nl
    do n = 1, x%nframes
      associate (f => x%frames(n))
        xml = xml//'      <Grid Name="step '//itoa(f%step)//'" GridType="Uniform">'//nl// &
              '        <Time Value="'//rtoa(f%t)//'"/>'//nl// &
              '        <Topology TopologyType="2DCoRectMesh" Dimensions="'//dims//'"/>'//nl// &
              '        <Geometry GeometryType="ORIGIN_DXDY">'//nl// &
              '          <DataItem Name="Origin" Dimensions="2" NumberType="Float" '// &
              'Precision="'//prec//'" Format="XML">'//rtoa(0.5_wp*x%dx + f%offset)//' '// &
              rtoa(0.5_wp*x%dx)//'</DataItem>'//nl// &
              '          <DataItem Name="Spacing" Dimensions="2" NumberType="Float" '// &
              'Precision="'//prec//'" Format="XML">'//rtoa(x%dx)//' '//rtoa(x%dx)// &
              '</DataItem>'//nl//'        </Geometry>'//nl
        do k = 1, size(f%fields)
          xml = xml//'        <Attribute Name="'//xml_escape(trim(f%fields(k)))// &
                '" AttributeType="Scalar" Center="Node">'//nl// &
                '          <DataItem Dimensions="'//dims//'" NumberType="Float" Precision="'// &
                prec//'" Format="HDF">'//xml_escape(x%h5_name//':'//f%group//'/'// &
                                                    trim(f%fields(k)))//'</DataItem>'//nl// &
                '        </Attribute>'//nl
        end do
        xml = xml//'      </Grid>'//nl
      end associate
    end do
    xml = xml//'    </Grid>'//nl//'  </Domain>'//nl//'</Xdmf>'

    tmp = x%path//'.tmp'
    open (newunit=u, file=tmp, status='replace', action='write', form='formatted', &
          iostat=ios, iomsg=msg)
    if (ios == 0) write (u, '(a)', iostat=ios, iomsg=msg) xml
    if (ios == 0) close (u, iostat=ios, iomsg=msg)
    if (ios /= 0) call fatal_local('cannot write '''//tmp//''': '//trim(msg))
    if (.not. rename_file(tmp, x%path)) &
      call fatal_local('cannot rename '''//tmp//''' to '''//x%path//'''')
  end subroutine xdmf_write

  !> Remove the sidecar file if it exists (one left by an earlier run would name groups the new
  !! HDF5 file does not have).
  subroutine xdmf_delete(x)
    type(xdmf_t), intent(in) :: x
    integer :: u, ios
    logical :: exists

    inquire (file=x%path, exist=exists)
    if (.not. exists) return
    open (newunit=u, file=x%path, status='old', iostat=ios)
    if (ios == 0) close (u, status='delete', iostat=ios)
    if (ios /= 0) call fatal_local('cannot remove the stale file '''//x%path//'''')
  end subroutine xdmf_delete

  !> Forget every frame.
  subroutine xdmf_free(x)
    type(xdmf_t), intent(inout) :: x
    x%nframes = 0
    if (allocated(x%frames)) deallocate (x%frames)
  end subroutine xdmf_free

  ! ---------------------------------------------------------------------------------------------

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

  !> Shortest-safe text of a real: 17 significant digits read back to the same value.
  pure function rtoa(x) result(s)
    real(wp), intent(in) :: x
    character(len=:), allocatable :: s
    character(len=32) :: buf
    write (buf, '(es24.16e3)') x
    s = trim(adjustl(buf))
  end function rtoa

end module dkt_xdmf

!> The XDMF sidecar `<dir>/<name>.xdmf` of an output file: the field snapshots written so far and
!> the XML that lets ParaView/VisIt open them as a time series on the lattice. Text only: the
!> HDF5 itself is written by dkt_io, which keeps an xdmf_t per open file. Every rank may record
!> frames; one rank (rank 0) writes the file.
!>
!> Each output time is a spatial collection of two grids: `fields`, a 3DCoRectMesh of one node
!> layer in the X-Y plane (x across, y along the channel, z = 0), with the scalar fields and the
!> vector `velocity` = (ux, uy, 0) joined from the ux and uy datasets by an XDMF function (no
!> extra data on disk); and `particles`, one Polyvertex point per disk at its centre with
!> `velocity` (vector), `radius`, `omega` and `id`. ParaView's "XDMF Reader" (XDMFReader in
!> pvpython) reads both; its Xdmf3 readers read the grids but not the joined vector.
!>
!> A run with disks also gets `<dir>/<name>_particles.xdmf`: the same particle grids, pointing
!> to the same datasets, as a temporal collection of its own. ParaView's XDMF reader names the
!> blocks of a repeated grid `particles`, `particles[1]`, ... by output time, so a block picked
!> in `<name>.xdmf` is gone at the next time; this file reads as one point set at every time,
!> and a Glyph filter on it draws the disks at whatever time is shown.
module dkt_xdmf
  use dkt_kinds, only: wp
  use dkt_filesystem, only: rename_file, remove_file, path_exists
  use dkt_text, only: itoa
  use dkt_errors, only: fatal_local
  implicit none
  private
  public :: xdmf_t, xdmf_init, xdmf_add_frame, xdmf_write, xdmf_delete, xdmf_free

  !> One field snapshot already in the HDF5 file.
  type :: frame_t
    integer :: step = 0
    real(wp) :: t = 0.0_wp      !! s
    real(wp) :: offset = 0.0_wp !! cm, window offset along y
    integer :: nparticles = 0   !! disks stored in <group>/particles (0: none)
    integer :: ny = 0           !! rows of its fields (a window that grows adds rows)
    character(len=:), allocatable :: group     !! HDF5 group of the snapshot, e.g. /fields/000010
    !> dataset names in that group; fixed length, because gfortran 12 loses the length of a
    !! deferred-length character array when the frames are copied into a grown array
    character(len=64), allocatable :: fields(:)
    !> bytes per value of each dataset, negative for an integer type (-2: int16, 8: float64)
    integer, allocatable :: bytes(:)
  end type frame_t

  !> The sidecar of one HDF5 file and the snapshots it lists.
  type :: xdmf_t
    character(len=:), allocatable :: path    !! <dir>/<name>.xdmf
    character(len=:), allocatable :: particles_path !! <dir>/<name>_particles.xdmf
    character(len=:), allocatable :: h5_name !! the HDF5 file, in the same directory
    integer :: nx = 0 !! global columns
    integer :: ny = 0 !! global rows at the open (each frame has its own)
    real(wp) :: dx = 0.0_wp !! cm, lattice spacing
    integer :: nframes = 0
    type(frame_t), allocatable :: frames(:)
  end type xdmf_t

  !> the end of a sidecar started by temporal_open
  character(len=*), parameter :: TEMPORAL_CLOSE = '    </Grid>'//new_line('a')//'  </Domain>'// &
                                 new_line('a')//'</Xdmf>'

contains

  !> Start an empty sidecar for the (nx, ny) lattice of spacing dx stored in `h5_name`, and the
  !! particle sidecar beside it (`path` without `.xdmf`, then `_particles.xdmf`). Nothing is
  !! written to disk.
  subroutine xdmf_init(x, path, h5_name, nx, ny, dx)
    type(xdmf_t), intent(inout) :: x
    character(len=*), intent(in) :: path    !! <dir>/<name>.xdmf
    character(len=*), intent(in) :: h5_name !! HDF5 file name relative to the sidecar
    integer, intent(in) :: nx, ny           !! global lattice size (columns, rows)
    real(wp), intent(in) :: dx              !! cm, lattice spacing
    integer :: stem

    x%path = path
    stem = len(path)
    if (stem > 5) then
      if (path(stem - 4:) == '.xdmf') stem = stem - 5
    end if
    x%particles_path = path(:stem)//'_particles.xdmf'
    x%h5_name = h5_name
    x%nx = nx
    x%ny = ny
    x%dx = dx
    x%nframes = 0
    if (allocated(x%frames)) deallocate (x%frames)
    allocate (x%frames(8))
  end subroutine xdmf_init

  !> Record the snapshot of `step` stored as datasets `names` in HDF5 group `group`, with
  !! `bytes(k)` bytes per value of dataset k (negative for integers), and `nparticles` disks in
  !! its sub-group `particles` (position, velocity, radius, omega, id); its fields hold `ny` rows
  !! (x%ny when absent: a window that grows, docs/model.md §5, writes more rows later).
  subroutine xdmf_add_frame(x, step, t, offset, group, names, bytes, nparticles, ny)
    type(xdmf_t), intent(inout) :: x
    integer, intent(in) :: step              !! time step
    real(wp), intent(in) :: t                !! s, simulated time
    real(wp), intent(in) :: offset           !! cm, y of the window bottom
    character(len=*), intent(in) :: group    !! absolute HDF5 path of the snapshot group
    character(len=*), intent(in) :: names(:) !! its datasets, one per field
    integer, intent(in) :: bytes(:)          !! bytes per value, negative for an integer type
    integer, intent(in) :: nparticles        !! disks in <group>/particles
    integer, intent(in), optional :: ny      !! rows of the fields
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
      f%nparticles = nparticles
      f%ny = x%ny
      if (present(ny)) f%ny = ny
      f%bytes = bytes
      if (maxval(len_trim(names)) > len(f%fields)) &
        call fatal_local('xdmf_add_frame: a field name is longer than 64 characters')
      allocate (f%fields(size(names)))
      do k = 1, size(names)
        f%fields(k) = trim(names(k))
      end do
    end associate
  end subroutine xdmf_add_frame

  !> Rewrite the sidecars with every snapshot so far: `<name>.xdmf` (main_xml) and, when a
  !! snapshot holds disks, `<name>_particles.xdmf` (particles_xml); without disks a particle
  !! sidecar left at that path is removed (a restart may have cut its snapshots). Each is
  !! written to a temporary name and renamed, so a reader never sees a half-written file.
  subroutine xdmf_write(x)
    type(xdmf_t), intent(in) :: x

    call write_text(x%path, main_xml(x))
    if (any(x%frames(1:x%nframes)%nparticles > 0)) then
      call write_text(x%particles_path, particles_xml(x))
    else
      call delete_file(x%particles_path)
    end if
  end subroutine xdmf_write

  !> Remove the sidecars if they exist (ones left by an earlier run would name groups the new
  !! HDF5 file does not have).
  subroutine xdmf_delete(x)
    type(xdmf_t), intent(in) :: x
    call delete_file(x%path)
    call delete_file(x%particles_path)
  end subroutine xdmf_delete

  !> Forget every frame.
  subroutine xdmf_free(x)
    type(xdmf_t), intent(inout) :: x
    x%nframes = 0
    if (allocated(x%frames)) deallocate (x%frames)
  end subroutine xdmf_free

  ! ---------------------------------------------------------------------------------------------

  !> The main sidecar: a temporal collection with, at each output time, the fields on the
  !! cell-centred nodes ((i - 1/2) dx, (j - 1/2) dx + offset, 0) and the disks. XDMF lists
  !! dimensions, origin and spacing slowest index first, i.e. (z, y, x).
  function main_xml(x) result(xml)
    type(xdmf_t), intent(in) :: x
    character(len=:), allocatable :: xml, dims, prec, h5
    character(len=1), parameter :: nl = new_line('a')
    integer :: n, k

    prec = itoa(storage_size(1.0_wp)/8)
    xml = temporal_open('run')
    do n = 1, x%nframes
      associate (f => x%frames(n))
        dims = '1 '//itoa(f%ny)//' '//itoa(x%nx)
        h5 = xml_escape(x%h5_name//':'//f%group)
        xml = xml//'      <Grid Name="step '//itoa(f%step)//'" GridType="Collection" '// &
              'CollectionType="Spatial">'//nl// &
              '        <Time Value="'//rtoa(f%t)//'"/>'//nl// &
              '        <Grid Name="fields" GridType="Uniform">'//nl// &
              '          <Topology TopologyType="3DCoRectMesh" Dimensions="'//dims//'"/>'//nl// &
              '          <Geometry GeometryType="ORIGIN_DXDYDZ">'//nl// &
              '            <DataItem Name="Origin" Dimensions="3" NumberType="Float" '// &
              'Precision="'//prec//'" Format="XML">0 '//rtoa(0.5_wp*x%dx + f%offset)//' '// &
              rtoa(0.5_wp*x%dx)//'</DataItem>'//nl// &
              '            <DataItem Name="Spacing" Dimensions="3" NumberType="Float" '// &
              'Precision="'//prec//'" Format="XML">'//rtoa(x%dx)//' '//rtoa(x%dx)//' '// &
              rtoa(x%dx)//'</DataItem>'//nl//'          </Geometry>'//nl
        do k = 1, size(f%fields)
          xml = xml//attribute(trim(f%fields(k)), 'Scalar', dims, f%bytes(k), &
                               h5//'/'//xml_escape(trim(f%fields(k))), '          ')
        end do
        if (any(f%fields == 'ux') .and. any(f%fields == 'uy')) &
          xml = xml//'          <Attribute Name="velocity" AttributeType="Vector" '// &
                'Center="Node">'//nl// &
                '            <DataItem ItemType="Function" Function="JOIN($0, $1, 0*$0)" '// &
                'Dimensions="'//dims//' 3">'//nl// &
                '              '//item(dims, storage_size(1.0_wp)/8, h5//'/ux')// &
                '              '//item(dims, storage_size(1.0_wp)/8, h5//'/uy')// &
                '            </DataItem>'//nl//'          </Attribute>'//nl
        xml = xml//'        </Grid>'//nl
        if (f%nparticles > 0) &
          xml = xml//particle_grid(f%nparticles, h5//'/particles', '        ', '')
        xml = xml//'      </Grid>'//nl
      end associate
    end do
    xml = xml//TEMPORAL_CLOSE
  end function main_xml

  !> The particle sidecar: a temporal collection of the particle grids alone, one per output
  !! time that has disks, each with its Time, pointing to the datasets main_xml names.
  function particles_xml(x) result(xml)
    type(xdmf_t), intent(in) :: x
    character(len=:), allocatable :: xml
    integer :: n

    xml = temporal_open('particles')
    do n = 1, x%nframes
      associate (f => x%frames(n))
        if (f%nparticles > 0) &
          xml = xml//particle_grid(f%nparticles, xml_escape(x%h5_name//':'//f%group)// &
                                   '/particles', '      ', rtoa(f%t))
      end associate
    end do
    xml = xml//TEMPORAL_CLOSE
  end function particles_xml

  !> The start of a sidecar: the XML header and a temporal collection named `name`, left open
  !! for its grids (TEMPORAL_CLOSE ends it).
  function temporal_open(name) result(xml)
    character(len=*), intent(in) :: name
    character(len=:), allocatable :: xml
    character(len=1), parameter :: nl = new_line('a')
    xml = '<?xml version="1.0" ?>'//nl//'<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>'//nl// &
          '<Xdmf Version="3.0">'//nl//'  <Domain>'//nl//'    <Grid Name="'//name// &
          '" GridType="Collection" CollectionType="Temporal">'//nl
  end function temporal_open

  !> Write `text` to `path` through a temporary file renamed over it.
  subroutine write_text(path, text)
    character(len=*), intent(in) :: path, text
    character(len=:), allocatable :: tmp
    character(len=512) :: msg
    integer :: u, ios

    tmp = path//'.tmp'
    open (newunit=u, file=tmp, status='replace', action='write', form='formatted', &
          iostat=ios, iomsg=msg)
    if (ios == 0) write (u, '(a)', iostat=ios, iomsg=msg) text
    if (ios == 0) close (u, iostat=ios, iomsg=msg)
    if (ios /= 0) call fatal_local('cannot write '''//tmp//''': '//trim(msg))
    if (.not. rename_file(tmp, path)) &
      call fatal_local('cannot rename '''//tmp//''' to '''//path//'''')
  end subroutine write_text

  !> Remove the file at `path` if it exists; a stale file that stays is fatal.
  subroutine delete_file(path)
    character(len=*), intent(in) :: path
    call remove_file(path)
    if (path_exists(path)) call fatal_local('cannot remove the stale file '''//path//'''')
  end subroutine delete_file

  !> The grid of `n` disks stored in HDF5 group `h5` (escaped "file:/group"): points at their
  !! centres with their velocity, radius, angular velocity and number; indented by `ind`, and
  !! with a Time element of value `time` (s) unless that is empty.
  function particle_grid(n, h5, ind, time) result(xml)
    integer, intent(in) :: n
    character(len=*), intent(in) :: h5, ind, time
    character(len=:), allocatable :: xml, in
    character(len=1), parameter :: nl = new_line('a')
    integer :: b
    b = storage_size(1.0_wp)/8
    in = ind//'  '
    xml = ind//'<Grid Name="particles" GridType="Uniform">'//nl
    if (len(time) > 0) xml = xml//in//'<Time Value="'//time//'"/>'//nl
    xml = xml//in//'<Topology TopologyType="Polyvertex" NumberOfElements="'//itoa(n)// &
          '" NodesPerElement="1"/>'//nl// &
          in//'<Geometry GeometryType="XYZ">'//nl// &
          in//'  '//item(itoa(n)//' 3', b, h5//'/position')// &
          in//'</Geometry>'//nl// &
          attribute('velocity', 'Vector', itoa(n)//' 3', b, h5//'/velocity', in)// &
          attribute('radius', 'Scalar', itoa(n), b, h5//'/radius', in)// &
          attribute('omega', 'Scalar', itoa(n), b, h5//'/omega', in)// &
          attribute('id', 'Scalar', itoa(n), -4, h5//'/id', in)// &
          ind//'</Grid>'//nl
  end function particle_grid

  !> A node-centred Attribute element holding one HDF5 dataset.
  function attribute(name, kind, dims, bytes, h5, ind) result(xml)
    character(len=*), intent(in) :: name, kind, dims, h5, ind
    integer, intent(in) :: bytes
    character(len=:), allocatable :: xml
    xml = ind//'<Attribute Name="'//xml_escape(name)//'" AttributeType="'//kind// &
          '" Center="Node">'//new_line('a')//ind//'  '//item(dims, bytes, h5)// &
          ind//'</Attribute>'//new_line('a')
  end function attribute

  !> A DataItem of an HDF5 dataset (`h5` escaped "file:/path") of `bytes` bytes per value,
  !! negative for an integer type; ends with a line break.
  function item(dims, bytes, h5) result(xml)
    character(len=*), intent(in) :: dims, h5
    integer, intent(in) :: bytes
    character(len=:), allocatable :: xml
    xml = '<DataItem Dimensions="'//dims//'" NumberType="'// &
          trim(merge('Int  ', 'Float', bytes < 0))//'" Precision="'//itoa(abs(bytes))// &
          '" Format="HDF">'//h5//'</DataItem>'//new_line('a')
  end function item

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

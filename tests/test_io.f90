!> Writer half of the dkt_io test; tests/test_io_readback.py runs it on 1..4 ranks and reads
!> the files back with h5py. Usage: test_io_prog <existing output dir>
!>
!> Writes into <dir>:
!> - io_fields.h5/.xdmf: /run, fields at step 0 (t = 0 s, offset 0 cm) and step 10
!>   (t = 0.125 s, offset 0.5 cm) with field k (1-based) at global column i, row j (1-based) equal
!>   to 1000 k + 10 j + i + step/4 (exact in binary), and three rows of /diagnostics/{a,b}
!>   where row r holds a = r, b = -r on rank 0 and garbage elsewhere (only rank 0 counts);
!> - io_overwrite.h5/.xdmf: written with step 0, then replaced (overwrite) by one with step 10
!>   only.
!> The slabs are deliberately uneven: with more than one rank, rank 0 holds a single row, and
!> with three or more, rank 1 holds none.
!> It checks itself, on every rank, that io_open refuses an existing file without overwrite and
!> reports a missing directory, naming the file in both messages. Exit status 0 when these
!> checks pass.
program test_io
  use iso_fortran_env, only: error_unit, compiler_version, compiler_options
  use mpi_f08, only: MPI_Comm, MPI_COMM_WORLD, MPI_INTEGER, MPI_SUM, MPI_Init, MPI_Finalize, &
                     MPI_Comm_rank, MPI_Comm_size, MPI_Allreduce
  use dkt_kinds, only: wp
  use dkt_io, only: io_t, io_open, io_write_run, io_write_fields, io_write_series, io_close
  implicit none

  integer, parameter :: nx = 5, ny = 7, nf = 5
  real(wp), parameter :: dx = 0.25_wp
  character(len=9), parameter :: names(nf) = &
                                 [character(len=9) :: 'rho', 'ux', 'uy', 'vorticity', 'pressure']
  character(len=*), parameter :: nl = new_line('a')
  type(MPI_Comm) :: comm
  type(io_t) :: io
  integer :: rank, nranks, y0, nyl, failures, total, r
  character(len=4096) :: dir
  character(len=:), allocatable :: err, path
  real(wp), allocatable :: fields(:, :, :)
  real(wp) :: row(2)

  call MPI_Init()
  comm = MPI_COMM_WORLD
  call MPI_Comm_rank(comm, rank)
  call MPI_Comm_size(comm, nranks)
  failures = 0
  if (command_argument_count() < 1) then
    if (rank == 0) write (error_unit, '(a)') 'usage: test_io_prog <existing output dir>'
    call MPI_Finalize()
    error stop 2
  end if
  call get_command_argument(1, dir)

  call slab(rank, nranks, y0, nyl)
  allocate (fields(nx, nyl, nf))

  ! --- a run: metadata, two snapshots, a short series -----------------------------------------
  call io_open(io, trim(dir), 'io_fields', comm, nx, ny, y0, nyl, dx, .false., err)
  call expect(err == '', 'io_open of a new file failed: '//err)
  call io_write_run(io, '&lbm'//nl//'  tau = 0.65'//nl//'/'//nl, '0.1.0', 'abc1234', nranks, &
                    compiler_version(), compiler_options(), &
                    [character(len=2) :: 'dx', 'nx', 'ny'], [dx, real(nx, wp), real(ny, wp)])
  call fill(0)
  call io_write_fields(io, 0, 0.0_wp, 0.0_wp, names, fields)
  do r = 1, 3
    row = [real(r, wp), -real(r, wp)]
    if (rank /= 0) row = huge(1.0_wp)
    call io_write_series(io, 'diagnostics', [character(len=1) :: 'a', 'b'], row)
  end do
  call fill(10)
  call io_write_fields(io, 10, 0.125_wp, 0.5_wp, names, fields)
  call io_close(io)

  ! --- an existing file is refused without overwrite, on every rank, naming the file ----------
  path = trim(dir)//'/io_fields.h5'
  call io_open(io, trim(dir), 'io_fields', comm, nx, ny, y0, nyl, dx, .false., err)
  call expect(err /= '', 'io_open accepted an existing file without overwrite')
  call expect(index(err, path) > 0, 'the refusal does not name '''//path//''': '//err)
  call expect(index(err, 'overwrite') > 0, 'the refusal does not say what to do: '//err)
  if (err == '') call io_close(io)

  ! --- a missing directory is reported, naming the file, on every rank ---------------------------
  path = trim(dir)//'/no_such_dir/io_fields.h5'
  call io_open(io, trim(dir)//'/no_such_dir', 'io_fields', comm, nx, ny, y0, nyl, dx, .false., err)
  call expect(index(err, path) > 0, 'a missing directory is not reported with the path: '//err)
  if (err == '') call io_close(io)

  ! --- overwrite replaces the file and its sidecar ---------------------------------------------
  call io_open(io, trim(dir), 'io_overwrite', comm, nx, ny, y0, nyl, dx, .false., err)
  call expect(err == '', 'io_open of a new file failed: '//err)
  call fill(0)
  call io_write_fields(io, 0, 0.0_wp, 0.0_wp, names, fields)
  call io_close(io)
  call io_open(io, trim(dir), 'io_overwrite', comm, nx, ny, y0, nyl, dx, .true., err)
  call expect(err == '', 'io_open with overwrite failed: '//err)
  call fill(10)
  call io_write_fields(io, 10, 0.125_wp, 0.5_wp, names, fields)
  call io_close(io)

  call MPI_Allreduce(failures, total, 1, MPI_INTEGER, MPI_SUM, comm)
  call MPI_Finalize()
  if (total > 0) error stop 1

contains

  !> Rank 0 one row, rank 1 none (from three ranks on), the rest split as evenly as possible.
  subroutine slab(rank, nranks, y0, nyl)
    integer, intent(in) :: rank, nranks
    integer, intent(out) :: y0, nyl
    integer :: first, nrest, rest, q
    if (nranks == 1) then
      y0 = 0
      nyl = ny
      return
    end if
    first = merge(2, 1, nranks >= 3) ! first rank of the even split
    nrest = nranks - first
    rest = ny - 1
    if (rank == 0) then
      y0 = 0
      nyl = 1
    else if (rank < first) then
      y0 = 1
      nyl = 0
    else
      q = rank - first
      nyl = rest/nrest + merge(1, 0, q >= nrest - mod(rest, nrest))
      y0 = 1 + q*(rest/nrest) + max(0, q - (nrest - mod(rest, nrest)))
    end if
  end subroutine slab

  subroutine fill(step)
    integer, intent(in) :: step
    integer :: i, j, k
    do k = 1, nf
      do j = 1, nyl
        do i = 1, nx
          fields(i, j, k) = 1000.0_wp*k + 10.0_wp*(y0 + j) + i + 0.25_wp*step
        end do
      end do
    end do
  end subroutine fill

  subroutine expect(ok, msg)
    logical, intent(in) :: ok
    character(len=*), intent(in) :: msg
    if (.not. ok) then
      failures = failures + 1
      write (error_unit, '(a,i0,a)') 'test_io: FAIL [rank ', rank, '] '//msg
    end if
  end subroutine expect

end program test_io

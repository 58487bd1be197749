!> Writer half of the dkt_io test; tests/test_io_readback.py runs it on 1..4 ranks and reads
!> the files back with h5py. Usage: test_io_prog <existing output dir> [bad_columns|bad_kind]
!>
!> Writes into <dir>:
!> - io_fields.h5/.xdmf: /run, fields at step 0 (t = 0 s, offset 0 cm) and step 10
!>   (t = 0.125 s, offset 0.5 cm) with field k (1-based) at global column i, row j (1-based) equal
!>   to 1000 k + 10 j + i + step/4 (exact in binary), and three rows of /diagnostics/{a,b}
!>   where row r holds a = r, b = -r on rank 0 and garbage elsewhere (only rank 0 counts);
!>   between the two snapshots, in the same file, 600 samples s = 1..600 of the 3-column tables
!>   /particles/{x,y,omega} (table k, column c: 100 k + 10 s + c + 1/4) and of the series
!>   /particles/t (s/8), rank 0's values, garbage elsewhere; the first sample writes the tables
!>   before the series, the others the series first (600 rows: dkt_io holds up to 256 rows of a
!>   dataset in memory, so they reach the file when a store fills, twice, and the last 88 when
!>   the first attribute is set). Then the attributes, rank 0's value
!>   given, a rank-dependent one elsewhere: /particles count = 3 (an integer, first written as
!>   7 and replaced), /particles/x unit = 'cm' (on a dataset), /diagnostics pattern =
!>   'repeated' and note = '' (strings), /checks/nested ratio = 0.375 (a real, creating both
!>   groups; first written as the string 'tbd' and replaced);
!> - io_overwrite.h5/.xdmf: written with step 0, then replaced (overwrite) by one with step 10
!>   only.
!> The slabs are deliberately uneven: with more than one rank, rank 0 holds a single row, and
!> with three or more, rank 1 holds none.
!> It checks itself, on every rank, that io_open refuses an existing file without overwrite and
!> reports a missing directory, naming the file in both messages. Exit status 0 when these
!> checks pass.
!>
!> With a second argument it instead writes io_bad.h5 and makes a mistake that must stop the
!> run with a message: bad_columns appends a 4-column row to the 3-column table
!> /particles/x; bad_kind appends a series row to that table.
program test_io
  use iso_fortran_env, only: error_unit, compiler_version, compiler_options
  use mpi_f08, only: MPI_Comm, MPI_COMM_WORLD, MPI_INTEGER, MPI_SUM, MPI_Init, MPI_Finalize, &
                     MPI_Comm_rank, MPI_Comm_size, MPI_Allreduce
  use dkt_kinds, only: wp
  use dkt_io, only: io_t, io_open, io_write_run, io_write_fields, io_write_series, &
                    io_write_table, io_write_attribute, io_close
  implicit none

  integer, parameter :: nx = 5, ny = 7, nf = 5
  real(wp), parameter :: dx = 0.25_wp
  character(len=9), parameter :: names(nf) = &
                                 [character(len=9) :: 'rho', 'ux', 'uy', 'vorticity', 'pressure']
  character(len=*), parameter :: nl = new_line('a')
  integer, parameter :: ncol = 3, nsamples = 600
  character(len=5), parameter :: tnames(3) = [character(len=5) :: 'x', 'y', 'omega']
  type(MPI_Comm) :: comm
  type(io_t) :: io
  integer :: rank, nranks, y0, nyl, failures, total, r, s
  character(len=4096) :: dir, mode
  character(len=:), allocatable :: err, path
  real(wp), allocatable :: fields(:, :, :)
  real(wp) :: row(2), table(ncol, size(tnames))

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
  call get_command_argument(2, mode)

  call slab(rank, nranks, y0, nyl)
  allocate (fields(nx, nyl, nf))
  if (mode /= '') call misuse(trim(mode)) ! never returns

  ! --- a run: metadata, two snapshots, a short series -----------------------------------------
  call io_open(io, trim(dir), 'io_fields', comm, nx, ny, y0, nyl, dx, .false., err)
  call expect(err == '', 'io_open of a new file failed: '//err)
  call io_write_run(io, '&lbm'//nl//'  tau = 0.65'//nl//'/'//nl, '0.1.0', 'abc1234', nranks, &
                    compiler_version(), compiler_options(), &
                    ['dx'], [dx], ['cm'])
  call io_write_attribute(io, '/run', 'nx', nx)
  call io_write_attribute(io, '/run', 'ny', ny)
  call fill(0)
  call io_write_fields(io, 0, 0.0_wp, 0.0_wp, names, fields)
  do r = 1, 3
    row = [real(r, wp), -real(r, wp)]
    if (rank /= 0) row = huge(1.0_wp)
    call io_write_series(io, 'diagnostics', [character(len=1) :: 'a', 'b'], row)
  end do

  ! --- particle tables and the time series side by side in one group --------------------------
  do s = 1, nsamples
    call fill_table(s)
    if (s > 1) call io_write_series(io, 'particles', ['t'], [t_sample(s)])
    call io_write_table(io, 'particles', tnames, table)
    if (s == 1) call io_write_series(io, 'particles', ['t'], [t_sample(s)])
  end do

  ! --- attributes: rank 0's value counts; rewriting replaces, also with another type ----------
  call io_write_attribute(io, '/particles', 'count', merge(7, 70 + rank, rank == 0))
  call io_write_attribute(io, '/particles', 'count', merge(ncol, 30 + rank, rank == 0))
  call io_write_attribute(io, '/particles/x', 'unit', trim(merge('cm     ', 'garbage', rank == 0)))
  call io_write_attribute(io, '/diagnostics', 'pattern', &
                          trim(merge('repeated            ', 'garbage from a rank ', rank == 0)))
  call io_write_attribute(io, '/diagnostics', 'note', repeat('x', merge(0, 5 + rank, rank == 0)))
  call io_write_attribute(io, '/checks/nested', 'ratio', 'tbd')
  call io_write_attribute(io, '/checks/nested', 'ratio', merge(0.375_wp, -1.0_wp*rank, rank == 0))

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

  !> Sample s of the tables: rank 0 the formula, other ranks values that must not be stored.
  subroutine fill_table(s)
    integer, intent(in) :: s
    integer :: c, k
    do k = 1, size(tnames)
      do c = 1, ncol
        table(c, k) = 100.0_wp*k + 10.0_wp*s + c + 0.25_wp
      end do
    end do
    if (rank /= 0) table = -huge(1.0_wp)
  end subroutine fill_table

  !> Sample s of the series /particles/t on this rank (rank 0's value is s/8).
  real(wp) function t_sample(s)
    integer, intent(in) :: s
    t_sample = merge(0.125_wp*s, -1.0_wp - rank, rank == 0)
  end function t_sample

  !> Make a mistake dkt_io must refuse with a message, in a fresh io_bad.h5. Never returns: the
  !! run stops in dkt_io, or here with exit status 1 if the mistake went through.
  subroutine misuse(what)
    character(len=*), intent(in) :: what
    real(wp) :: wide(ncol + 1, 1)
    call io_open(io, trim(dir), 'io_bad', comm, nx, ny, y0, nyl, dx, .false., err)
    call expect(err == '', 'io_open of a new file failed: '//err)
    call fill_table(1)
    call io_write_table(io, 'particles', tnames(1:1), table(:, 1:1))
    select case (what)
    case ('bad_columns')
      wide = 1.0_wp
      call io_write_table(io, 'particles', tnames(1:1), wide)
    case ('bad_kind')
      call io_write_series(io, 'particles', tnames(1:1), [1.0_wp])
    case default
      call expect(.false., 'unknown mode '''//what//'''')
    end select
    call expect(.false., what//': dkt_io accepted the mistake')
    call io_close(io)
    call MPI_Finalize()
    error stop 1
  end subroutine misuse

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

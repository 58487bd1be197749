!> STREAM-like memory bandwidth of this machine: the ceiling of the memory-bound lattice sweep
!> (tests/perf/roofline.py turns it into MLUPS per storage layout).
!>
!> Every MPI rank allocates its own two arrays (nothing is shared or sent between ranks) and all
!> ranks run each kernel at the same time, started together by a barrier, so that n ranks
!> measure what n cores draw from memory at once. The kernels, on real64 elements:
!>
!>   copy    a(i) = b(i)       counted 16 B per element (b read, a written). A plain store also
!>                             reads the cache line of a before writing it (write-allocate):
!>                             24 B cross the memory bus; the access pattern of the sweep that
!>                             reads one lattice and writes the other.
!>   update  a(i) = a(i) + s   counted 16 B (a read and written back in place): no write-allocate,
!>                             the access pattern of in-place streaming on one lattice.
!>   sum     s = s + b(i)      counted 8 B, read only: the bus's read ceiling.
!>
!> GB/s are counted bytes (10^9 B) per second, write-allocate not included; the bus traffic of
!> copy is 24/16 of its figure. The time of a repeat is the slowest rank's; the total is all
!> ranks' bytes over it, per rank is total / ranks. The copy loop is compiled without gfortran's
!> memcpy substitution (tests/perf.cmake), whose large-size path avoids the write-allocate.
!>
!> usage: [mpiexec -n R] stream_copy [MIB_PER_RANK [REPEATS]]
!>   MIB_PER_RANK  both arrays of one rank together, MiB; 0 or none: 8 times the last-level
!>                 cache (read from /sys/devices/system/cpu/cpu0/cache), so that no kernel runs
!>                 from the cache
!>   REPEATS       timed runs of each kernel (default 10), after one untimed warm-up
!> Exit status 1 for bad arguments or when the arrays do not hold the values the kernels put
!> there (a compiler that dropped a kernel would be timed as infinitely fast).
program stream_copy
  use iso_fortran_env, only: real64, int64, output_unit, error_unit
  use mpi_f08, only: MPI_Init, MPI_Finalize, MPI_Comm_rank, MPI_Comm_size, MPI_Barrier, &
                     MPI_Wtime, MPI_Allreduce, MPI_Bcast, MPI_Abort, MPI_COMM_WORLD, MPI_MAX, &
                     MPI_LOR, MPI_DOUBLE_PRECISION, MPI_INTEGER, MPI_INTEGER8, MPI_LOGICAL, &
                     MPI_IN_PLACE
  implicit none

  integer, parameter :: dp = real64
  integer, parameter :: i8 = int64
  integer, parameter :: mib = 1048576 !! bytes in a MiB
  integer, parameter :: element_bytes = 8 !! one real64
  integer, parameter :: lanes = 16 !! independent partial sums of the sum kernel; n is a multiple
  integer, parameter :: cache_factor = 8 !! default working set per rank, in last-level caches
  integer(i8), parameter :: fallback_cache = 32_i8*mib !! when /sys does not say
  integer, parameter :: default_repeats = 10
  integer, parameter :: nkernels = 3
  character(len=6), parameter :: names(nkernels) = ['copy  ', 'update', 'sum   ']
  integer, parameter :: counted(nkernels) = [16, 16, 8] !! bytes per element, see above
  integer, parameter :: write_allocate(nkernels) = [8, 0, 0] !! write-allocate bytes per element
  real(dp), parameter :: gb = 1.0e9_dp

  real(dp), allocatable :: a(:), b(:), seconds(:, :)
  real(dp) :: t0, total, partial, expected_sum
  integer(i8) :: cache_bytes, per_rank_bytes, n
  integer :: rank, nranks, repeats, r, k, status
  character(len=256) :: cache_source
  logical :: bad, any_bad

  call MPI_Init()
  call MPI_Comm_rank(MPI_COMM_WORLD, rank)
  call MPI_Comm_size(MPI_COMM_WORLD, nranks)

  if (rank == 0) then
    call last_level_cache(cache_bytes, cache_source)
    call read_arguments(cache_bytes, per_rank_bytes, repeats, status)
    if (status /= 0) call MPI_Abort(MPI_COMM_WORLD, 1)
  end if
  call MPI_Bcast(cache_bytes, 1, MPI_INTEGER8, 0, MPI_COMM_WORLD)
  call MPI_Bcast(per_rank_bytes, 1, MPI_INTEGER8, 0, MPI_COMM_WORLD)
  call MPI_Bcast(repeats, 1, MPI_INTEGER, 0, MPI_COMM_WORLD)

  ! two arrays per rank, a whole number of sum lanes each
  n = per_rank_bytes/(2_i8*element_bytes)
  n = max(lanes, (n/lanes)*lanes)
  allocate (a(n), b(n), seconds(repeats, nkernels))
  ! first touch by the owning rank, values the checks below can predict
  a = 0.0_dp
  b = 1.0_dp

  if (rank == 0) then
    write (output_unit, '(a,i0,a,i0,a,i0,a,f0.1,a)') 'stream_copy: ', nranks, ' rank(s), ', &
      n, ' real64 per array, 2 arrays per rank (', 2_i8*n*element_bytes, ' bytes, ', &
      real(2_i8*n*element_bytes, dp)/real(cache_bytes, dp), ' x the last-level cache)'
    write (output_unit, '(a,i0,a,a)') 'last-level cache: ', cache_bytes, ' bytes, from ', &
      trim(cache_source)
    write (output_unit, '(a,i0,a)') 'repeats: ', repeats, ' timed (after 1 warm-up); GB = 1e9 B'
  end if

  ! r = 0 is the warm-up (page faults, clocks), not recorded
  do r = 0, repeats
    do k = 1, nkernels
      call MPI_Barrier(MPI_COMM_WORLD)
      t0 = MPI_Wtime()
      select case (k)
      case (1)
        call copy(a, b)
      case (2)
        call update(a, 1.0_dp)
      case (3)
        call sum_lanes(b, partial)
      end select
      total = MPI_Wtime() - t0
      call MPI_Allreduce(MPI_IN_PLACE, total, 1, MPI_DOUBLE_PRECISION, MPI_MAX, MPI_COMM_WORLD)
      if (r > 0) seconds(r, k) = total
    end do
  end do

  ! every repeat copies b (all 1) into a and adds 1: a = 2 now; b sums to n
  expected_sum = real(n, dp)
  bad = any(a /= 2.0_dp) .or. any(b /= 1.0_dp) .or. partial /= expected_sum
  call MPI_Allreduce(bad, any_bad, 1, MPI_LOGICAL, MPI_LOR, MPI_COMM_WORLD)

  if (rank == 0) then
    write (output_unit, '(a)') 'kernel  counted_B/elem  write_allocate_B/elem  '// &
      'best_GB/s_total  median_GB/s_total  worst_GB/s_total  best_GB/s_per_rank  '// &
      'median_GB/s_per_rank'
    do k = 1, nkernels
      call report(names(k), counted(k), write_allocate(k), seconds(:, k))
    end do
    if (any_bad) write (error_unit, '(a)') 'stream_copy: the arrays do not hold the values '// &
      'the kernels write: a kernel was not run as written'
  end if
  call MPI_Finalize()
  if (any_bad) error stop 1

contains

  !> a(i) = b(i), one load and one store per element (no memcpy: see tests/perf.cmake)
  subroutine copy(a, b)
    real(dp), intent(out) :: a(:)
    real(dp), intent(in) :: b(:)
    integer(i8) :: i
    do i = 1, size(a, kind=i8)
      a(i) = b(i)
    end do
  end subroutine copy

  !> a(i) = a(i) + s: read and written in place
  subroutine update(a, s)
    real(dp), intent(inout) :: a(:)
    real(dp), intent(in) :: s
    integer(i8) :: i
    do i = 1, size(a, kind=i8)
      a(i) = a(i) + s
    end do
  end subroutine update

  !> s = sum of b in `lanes` independent partial sums, so that the adds vectorise and their
  !> latency hides behind the loads (a single running sum is slower than the memory)
  subroutine sum_lanes(b, s)
    real(dp), intent(in) :: b(:)
    real(dp), intent(out) :: s
    real(dp) :: acc(lanes)
    integer(i8) :: i
    acc = 0.0_dp
    do i = 1, size(b, kind=i8), lanes
      acc = acc + b(i:i + lanes - 1)
    end do
    s = sum(acc)
  end subroutine sum_lanes

  !> One row of the table: bandwidth from the best, median and worst of the slowest-rank times.
  subroutine report(name, counted_bytes, allocate_bytes, times)
    character(len=*), intent(in) :: name
    integer, intent(in) :: counted_bytes, allocate_bytes
    real(dp), intent(in) :: times(:)
    real(dp) :: bytes, best, median, worst
    bytes = real(counted_bytes, dp)*real(n, dp)*real(nranks, dp)
    best = bytes/minval(times)/gb
    median = bytes/median_of(times)/gb
    worst = bytes/maxval(times)/gb
    write (output_unit, '(a6,2i8,5f12.2)') name, counted_bytes, allocate_bytes, best, median, &
      worst, best/nranks, median/nranks
  end subroutine report

  !> Median of a short list (insertion sort of a copy).
  real(dp) function median_of(x)
    real(dp), intent(in) :: x(:)
    real(dp) :: s(size(x)), v
    integer :: i, j, m
    s = x
    do i = 2, size(s)
      v = s(i)
      j = i - 1
      do while (j >= 1)
        if (s(j) <= v) exit
        s(j + 1) = s(j)
        j = j - 1
      end do
      s(j + 1) = v
    end do
    m = size(s)
    if (mod(m, 2) == 1) then
      median_of = s((m + 1)/2)
    else
      median_of = 0.5_dp*(s(m/2) + s(m/2 + 1))
    end if
  end function median_of

  !> The size of the highest cache level cpu0 reports in /sys (Linux), or the fallback.
  subroutine last_level_cache(bytes, source)
    integer(i8), intent(out) :: bytes
    character(len=*), intent(out) :: source
    character(len=*), parameter :: base = '/sys/devices/system/cpu/cpu0/cache/index'
    character(len=64) :: text
    character(len=128) :: dir
    integer :: index, level, best_level, unit, ios
    integer(i8) :: size_bytes
    bytes = fallback_cache
    source = 'nowhere (/sys not readable): assumed 32 MiB'
    best_level = 0
    do index = 0, 9
      write (dir, '(a,i0,a)') base, index, '/'
      open (newunit=unit, file=trim(dir)//'level', status='old', action='read', iostat=ios)
      if (ios /= 0) cycle
      read (unit, *, iostat=ios) level
      close (unit)
      if (ios /= 0 .or. level <= best_level) cycle
      open (newunit=unit, file=trim(dir)//'size', status='old', action='read', iostat=ios)
      if (ios /= 0) cycle
      read (unit, '(a)', iostat=ios) text
      close (unit)
      if (ios /= 0) cycle
      size_bytes = parse_size(text)
      if (size_bytes <= 0) cycle
      best_level = level
      bytes = size_bytes
      write (source, '(a,a,i0,a,a,a)') trim(dir), 'size (L', level, ', "', trim(text), '")'
    end do
  end subroutine last_level_cache

  !> '32768K' -> 33554432; 0 for text it cannot read.
  integer(i8) function parse_size(text)
    character(len=*), intent(in) :: text
    character(len=len(text)) :: t
    integer(i8) :: value, factor
    integer :: last, ios
    parse_size = 0
    t = adjustl(text)
    last = len_trim(t)
    if (last == 0) return
    factor = 1
    select case (t(last:last))
    case ('K', 'k')
      factor = 1024_i8
    case ('M', 'm')
      factor = 1024_i8**2
    case ('G', 'g')
      factor = 1024_i8**3
    end select
    if (factor /= 1) last = last - 1
    read (t(1:last), *, iostat=ios) value
    if (ios /= 0 .or. value <= 0) return
    parse_size = value*factor
  end function parse_size

  !> MIB_PER_RANK and REPEATS from the command line, or their defaults.
  subroutine read_arguments(cache, bytes, nrep, stat)
    integer(i8), intent(in) :: cache
    integer(i8), intent(out) :: bytes
    integer, intent(out) :: nrep, stat
    integer(i8) :: value
    bytes = cache_factor*cache
    nrep = default_repeats
    call integer_argument(1, 'MIB_PER_RANK', 0_i8, value, stat)
    if (stat == 0 .and. value > 0) bytes = value*mib
    if (stat == 0) call integer_argument(2, 'REPEATS', 1_i8, value, stat)
    if (stat == 0 .and. value > 0) nrep = int(value)
  end subroutine read_arguments

  !> Command-line argument `position` as a whole number >= minimum; 0 when it is not given,
  !> stat 1 (and a message) when it is not such a number.
  subroutine integer_argument(position, name, minimum, value, stat)
    integer, intent(in) :: position
    character(len=*), intent(in) :: name
    integer(i8), intent(in) :: minimum
    integer(i8), intent(out) :: value
    integer, intent(out) :: stat
    character(len=64) :: arg
    integer :: ios
    value = 0
    stat = 0
    if (command_argument_count() < position) return
    call get_command_argument(position, arg)
    read (arg, *, iostat=ios) value
    if (ios /= 0 .or. value < minimum .or. value > huge(1)) then
      write (error_unit, '(a,a,i0,a)') 'stream_copy: ', name//' must be a whole number >= ', &
        minimum, ', not "'//trim(arg)//'" (usage: stream_copy [MIB_PER_RANK [REPEATS]])'
      stat = 1
    end if
  end subroutine integer_argument

end program stream_copy

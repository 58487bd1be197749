!> The 1-D slab decomposition along the channel axis y (docs/design.md, "Data layout").
!>
!> Rank r holds global rows y0+1 .. y0+nyl of all nx columns. A lattice is stored as
!> f(0:nxp-1, 0:nyl+1, 0:8): ghost columns 0 and nx+1 for the side boundaries, halo rows 0 and
!> nyl+1 for the neighbours or the channel ends, and padding to nxp so that consecutive
!> population planes do not sit a multiple of 4 KiB apart (cache-set aliasing made a 512 x 512
!> lattice run 2-4 times slower than 500 x 500). Only the three populations that cross a face
!> travel in the halo exchange.
!>
!> The rows split evenly at the start (slabs differ by one row when they do not divide); a
!> balanced split (domain_split) may move the borders during a run so that each rank's work is
!> equal, and every rank knows every border (`starts`). nxp is chosen for the tallest slab and
!> is the same on every rank, and every exchange between slabs sends columns that both sides
!> count from nx alone: a message never depends on the sender's slab height.
module dkt_domain
  use mpi_f08, only: MPI_Comm, MPI_Request, MPI_Comm_dup, MPI_Comm_rank, MPI_Comm_size, &
                     MPI_Comm_free, MPI_Irecv, MPI_Isend, MPI_Waitall, MPI_PROC_NULL, &
                     MPI_STATUSES_IGNORE, MPI_Sendrecv, MPI_STATUS_IGNORE, MPI_Alltoallv, &
                     MPI_INTEGER2, MPI_Bcast, MPI_Allgatherv
  use iso_fortran_env, only: int16
  use dkt_kinds, only: wp, sp, i8, mpi_wp
  use dkt_store, only: lattice_t
  use dkt_timers, only: wait_start, wait_stop
  implicit none
  private
  public :: domain_t, domain_init, domain_free, domain_rows_for, halo_start, halo_finish, &
            domain_edge_rows, max_ranks_for, MIN_SLAB_ROWS, domain_resize, domain_move_rows, &
            domain_fill_new_rows, domain_split, domain_rows_of, domain_owner_of_row, &
            domain_gather_rows, domain_row_at

  !> fewest rows a slab may hold: the open-end rule (E5) reads the row next to the end row
  integer, parameter :: MIN_SLAB_ROWS = 2
  integer, parameter :: up_pops(3) = [2, 5, 6]   !! populations with c_y = +1
  integer, parameter :: down_pops(3) = [4, 7, 8] !! populations with c_y = -1
  integer, parameter :: TAG_UP = 11, TAG_DOWN = 12, TAG_EDGE_UP = 13, TAG_EDGE_DOWN = 14

  type :: domain_t
    type(MPI_Comm) :: comm           !! duplicated communicator of the run
    integer :: rank = 0, nranks = 1
    integer :: nx = 0, ny = 0        !! global cells across (x) and along (y) the channel
    integer :: nxp = 0               !! padded first extent of a lattice (>= nx + 2)
    integer :: y0 = 0                !! rows of the ranks below this one
    integer :: nyl = 0               !! rows of this slab
    !> every rank's rows: rank r holds global rows starts(r)+1 .. starts(r+1) (starts(0) = 0,
    !! starts(nranks) = ny)
    integer, allocatable :: starts(:)
    integer :: below = MPI_PROC_NULL !! neighbour ranks (MPI_PROC_NULL at a closed or open end)
    integer :: above = MPI_PROC_NULL
    logical :: periodic_x = .false., periodic_y = .false.
    logical :: has_lower_end = .false. !! this slab holds global row 1 of a non-periodic channel
    logical :: has_upper_end = .false. !! this slab holds global row ny of a non-periodic channel
    real(wp), allocatable :: sbuf_up(:), sbuf_dn(:), rbuf_up(:), rbuf_dn(:)
    !> the same for 16-bit codes (lbm.precision = 'half'), which travel as 2-byte integers
    integer(int16), allocatable :: hbuf_up(:), hbuf_dn(:), hrbuf_up(:), hrbuf_dn(:)
    type(MPI_Request) :: req(4)
  end type domain_t

contains

  !> Rows of rank r when ny rows are shared by n ranks: as even as possible, lower ranks first.
  pure subroutine domain_rows_for(ny, n, r, y0, nyl)
    integer, intent(in) :: ny, n, r
    integer, intent(out) :: y0, nyl
    integer :: base, extra
    base = ny/n
    extra = mod(ny, n)
    nyl = base + merge(1, 0, r < extra)
    y0 = r*base + min(r, extra)
  end subroutine domain_rows_for

  !> The largest rank count whose slabs all hold at least min_rows rows.
  pure integer function max_ranks_for(ny, min_rows)
    integer, intent(in) :: ny, min_rows
    max_ranks_for = max(1, ny/min_rows)
  end function max_ranks_for

  !> Split ny rows over the ranks of comm. err is set (on every rank alike) when a slab would be
  !! thinner than min_rows.
  subroutine domain_init(dom, comm, nx, ny, periodic_x, periodic_y, min_rows, err)
    type(domain_t), intent(out) :: dom
    type(MPI_Comm), intent(in) :: comm
    integer, intent(in) :: nx, ny, min_rows
    logical, intent(in) :: periodic_x, periodic_y
    character(len=:), allocatable, intent(out) :: err
    character(len=256) :: msg
    integer :: smallest

    err = ''
    call MPI_Comm_dup(comm, dom%comm)
    call MPI_Comm_rank(dom%comm, dom%rank)
    call MPI_Comm_size(dom%comm, dom%nranks)
    dom%nx = nx
    dom%ny = ny
    dom%periodic_x = periodic_x
    dom%periodic_y = periodic_y
    smallest = ny/dom%nranks
    if (smallest < min_rows) then
      ! (a slab has more than one row, so only the rank counts can be 1)
      write (msg, '(a,i0,a,i0,a,a,i0,a,i0,a,i0,a,a)') 'the channel has ', ny, ' rows; on ', &
        dom%nranks, trim(merge(' rank ', ' ranks', dom%nranks == 1)), ' a slab would hold ', &
        smallest, ' but needs at least ', min_rows, '; run on at most ', &
        max_ranks_for(ny, min_rows), trim(merge(' rank ', ' ranks', &
                                                max_ranks_for(ny, min_rows) == 1)), &
        ', or refine lbm.dx / lengthen domain.height'
      err = trim(msg)
      return
    end if
    ! one padded extent for all ranks (the tallest slab's), so a row means the same on both
    ! sides of every exchange
    call domain_split(dom, even_starts(ny, dom%nranks))

    if (dom%rank > 0) then
      dom%below = dom%rank - 1
    else if (periodic_y) then
      dom%below = dom%nranks - 1
    end if
    if (dom%rank < dom%nranks - 1) then
      dom%above = dom%rank + 1
    else if (periodic_y) then
      dom%above = 0
    end if
    dom%has_lower_end = dom%rank == 0 .and. .not. periodic_y
    dom%has_upper_end = dom%rank == dom%nranks - 1 .and. .not. periodic_y
    allocate (dom%sbuf_up(3*nx), dom%sbuf_dn(3*nx), dom%rbuf_up(3*nx), dom%rbuf_dn(3*nx))
    allocate (dom%hbuf_up(3*nx), dom%hbuf_dn(3*nx), dom%hrbuf_up(3*nx), dom%hrbuf_dn(3*nx))
  end subroutine domain_init

  !> The slabs of the same ranks over ny rows (a window that grows, docs/model.md §5): this
  !! rank's rows and the padded extent as domain_init sets them for ny; the neighbours, the
  !! ends and the halo buffers (sized by nx) stay. ny is at least the present row count.
  pure subroutine domain_resize(dom, ny)
    type(domain_t), intent(inout) :: dom
    integer, intent(in) :: ny
    dom%ny = ny
    call domain_split(dom, even_starts(ny, dom%nranks))
  end subroutine domain_resize

  !> The borders of the even split of ny rows over n ranks (domain_rows_for).
  pure function even_starts(ny, n) result(starts)
    integer, intent(in) :: ny, n
    integer :: starts(0:n), r, nyl
    do r = 0, n - 1
      call domain_rows_for(ny, n, r, starts(r), nyl)
    end do
    starts(n) = ny
  end function even_starts

  !> The slabs of the same ranks split at the borders `starts` (rank r: rows starts(r)+1 ..
  !! starts(r+1); starts(0) = 0, starts(nranks) = dom%ny, every slab at least one row): this
  !! rank's rows and the padded extent of the tallest slab. The caller moves the rows
  !! (domain_move_rows) from a copy of the domain as it was.
  pure subroutine domain_split(dom, starts)
    type(domain_t), intent(inout) :: dom
    integer, intent(in) :: starts(0:)
    dom%starts = starts
    dom%y0 = starts(dom%rank)
    dom%nyl = starts(dom%rank + 1) - starts(dom%rank)
    dom%nxp = padded_extent(dom%nx, maxval(starts(1:dom%nranks) - starts(0:dom%nranks - 1)))
  end subroutine domain_split

  !> A value per row of every slab, in global row order on every rank: `mine` holds this
  !! slab's rows 1..nyl, `every` (ny) receives them all.
  subroutine domain_gather_rows(dom, mine, every)
    type(domain_t), intent(in) :: dom
    real(wp), intent(in) :: mine(:)
    real(wp), intent(out) :: every(:)
    call wait_start()
    call MPI_Allgatherv(mine, dom%nyl, mpi_wp, every, &
                        dom%starts(1:dom%nranks) - dom%starts(0:dom%nranks - 1), &
                        dom%starts(0:dom%nranks - 1), mpi_wp, dom%comm)
    call wait_stop()
  end subroutine domain_gather_rows

  !> The rows of rank r: global rows y0+1 .. y0+nyl.
  pure subroutine domain_rows_of(dom, r, y0, nyl)
    type(domain_t), intent(in) :: dom
    integer, intent(in) :: r
    integer, intent(out) :: y0, nyl
    y0 = dom%starts(r)
    nyl = dom%starts(r + 1) - dom%starts(r)
  end subroutine domain_rows_of

  !> The global row (1..ny) that holds the finite height y (lattice units; row j covers
  !! [j - 1, j)), the channel's first or last row for a height beyond it.
  pure integer function domain_row_at(dom, y) result(jg)
    type(domain_t), intent(in) :: dom
    real(wp), intent(in) :: y
    jg = int(min(max(y, 0.0_wp), real(dom%ny - 1, wp))) + 1
  end function domain_row_at

  !> The rank that holds global row jg (1..ny): a bisection of the borders.
  pure integer function domain_owner_of_row(dom, jg) result(r)
    type(domain_t), intent(in) :: dom
    integer, intent(in) :: jg
    integer :: lo, hi, mid
    lo = 0
    hi = dom%nranks - 1
    do while (lo < hi)
      mid = (lo + hi + 1)/2
      if (dom%starts(mid) < jg) then
        lo = mid
      else
        hi = mid - 1
      end if
    end do
    r = lo
  end function domain_owner_of_row

  !> Move the populations of rows 1..nyl (columns 1..nx) of `src`, split as `old` splits its
  !! rows, into `dst`, split as `new` splits its own (the same ranks and columns, new%ny >=
  !! old%ny): each global row goes to the rank that holds it in `new`, in one MPI_Alltoallv.
  !! Both sides count every message from the two splits' borders, which every rank knows, so
  !! the sizes agree on any split. Rows beyond old%ny are not touched: the caller fills them.
  !! Stored values travel as they are (a 4-byte value or a 16-bit code in the 8-byte buffer
  !! converts exactly).
  subroutine domain_move_rows(old, new, src, dst)
    type(domain_t), intent(in) :: old, new
    type(lattice_t), intent(in) :: src
    type(lattice_t), intent(inout) :: dst
    integer :: scount(0:old%nranks - 1), sdispl(0:old%nranks - 1)
    integer :: rcount(0:old%nranks - 1), rdispl(0:old%nranks - 1)
    real(wp), allocatable :: sbuf(:), rbuf(:)
    integer :: r, y0, nyl, lo, hi, j, m, nx
    nx = old%nx
    do r = 0, old%nranks - 1
      ! to r: my old rows that r holds in the new split; from r: r's old rows that I hold
      call domain_rows_of(new, r, y0, nyl)
      scount(r) = 9*nx*max(0, min(old%y0 + old%nyl, y0 + nyl) - max(old%y0, y0))
      call domain_rows_of(old, r, y0, nyl)
      rcount(r) = 9*nx*max(0, min(new%y0 + new%nyl, y0 + nyl) - max(new%y0, y0))
    end do
    sdispl(0) = 0
    rdispl(0) = 0
    do r = 1, old%nranks - 1
      sdispl(r) = sdispl(r - 1) + scount(r - 1)
      rdispl(r) = rdispl(r - 1) + rcount(r - 1)
    end do
    allocate (sbuf(max(1, sum(scount))), rbuf(max(1, sum(rcount))))
    ! the destinations hold consecutive rows, so my rows in order are the messages in order
    do j = 1, old%nyl
      call stored_row(src, j, nx, sbuf(9*nx*(j - 1) + 1:9*nx*j))
    end do
    call MPI_Alltoallv(sbuf, scount, sdispl, mpi_wp, rbuf, rcount, rdispl, mpi_wp, old%comm)
    ! likewise the sources: my new rows that existed, in order
    lo = new%y0 + 1
    hi = min(new%y0 + new%nyl, old%ny)
    m = 0
    do j = lo - new%y0, hi - new%y0
      call store_row(rbuf(m + 1:m + 9*nx), dst, j, nx)
      m = m + 9*nx
    end do
  end subroutine domain_move_rows

  !> Fill the rows a window's growth added (global rows old%ny+1..new%ny of `dst`, split as
  !! `new`) with copies of the old upper end row of `src` (split as `old`), stored values as
  !! they are: the zero normal gradient the outflow end (E5) keeps. The fluid that the settling
  !! particles displace leaves through that end; rows added at rest would stop it at once and
  !! send a pressure wave down the channel onto the particles (docs/model.md §5). The rank
  !! that held the row (the last one) sends it to all in one broadcast.
  subroutine domain_fill_new_rows(old, new, src, dst)
    type(domain_t), intent(in) :: old, new
    type(lattice_t), intent(in) :: src
    type(lattice_t), intent(inout) :: dst
    real(wp) :: row(9*old%nx)
    integer :: j
    if (old%rank == old%nranks - 1) call stored_row(src, old%nyl, old%nx, row)
    call MPI_Bcast(row, size(row), mpi_wp, old%nranks - 1, old%comm)
    do j = max(1, old%ny - new%y0 + 1), new%nyl
      call store_row(row, dst, j, old%nx)
    end do
  end subroutine domain_fill_new_rows

  !> Row j (columns 1..nx) of `lat` as stored, the nine populations one after the other, in
  !! 8 bytes (a 4-byte value or a 16-bit code converts exactly): what rows travel as.
  subroutine stored_row(lat, j, nx, v)
    type(lattice_t), intent(in) :: lat
    integer, intent(in) :: j, nx
    real(wp), intent(out) :: v(nx, 0:8)
    integer :: k
    do k = 0, 8
      if (lat%half) then
        v(:, k) = real(lat%h(1:nx, j, k), wp)
      else if (lat%single) then
        v(:, k) = real(lat%s(1:nx, j, k), wp)
      else
        v(:, k) = lat%d(1:nx, j, k)
      end if
    end do
  end subroutine stored_row

  !> The inverse of stored_row: row j of `lat` from v.
  subroutine store_row(v, lat, j, nx)
    integer, intent(in) :: j, nx
    real(wp), intent(in) :: v(nx, 0:8)
    type(lattice_t), intent(inout) :: lat
    integer :: k
    do k = 0, 8
      if (lat%half) then
        lat%h(1:nx, j, k) = int(v(:, k), int16)
      else if (lat%single) then
        lat%s(1:nx, j, k) = real(v(:, k), sp)
      else
        lat%d(1:nx, j, k) = v(:, k)
      end if
    end do
  end subroutine store_row

  subroutine domain_free(dom)
    type(domain_t), intent(inout) :: dom
    call MPI_Comm_free(dom%comm)
  end subroutine domain_free

  !> Smallest nxp >= nx + 2 for which the nine population planes of nxp*(nyl+2) values all
  !! start at least 256 bytes apart modulo 4 KiB.
  pure integer function padded_extent(nx, nyl) result(nxp)
    integer, intent(in) :: nx, nyl
    integer(i8) :: plane, off
    integer :: k
    logical :: good
    nxp = nx + 2
    do
      plane = int(nxp, i8)*int(nyl + 2, i8)*8_i8
      good = .true.
      do k = 1, 8
        off = modulo(k*plane, 4096_i8)
        if (min(off, 4096_i8 - off) < 256_i8) good = .false.
      end do
      if (good .or. nxp > nx + 64) exit
      nxp = nxp + 1
    end do
  end function padded_extent

  !> Post the halo exchange of the post-collision populations that cross the slab faces:
  !! c_y = +1 from row nyl go up into the upper neighbour's row 0, c_y = -1 from row 1 go down
  !! into the lower neighbour's row nyl+1. Columns 1..nx only; ghost columns are set locally.
  !! The stored values travel as they are: a 4-byte value in the 8-byte buffer converts exactly
  !! both ways; 16-bit codes travel in 2-byte buffers, in the same messages.
  subroutine halo_start(dom, f)
    type(domain_t), intent(inout) :: dom
    type(lattice_t), intent(in) :: f
    integer :: k, nx, n
    nx = dom%nx
    n = 3*nx
    if (f%half) then
      call MPI_Irecv(dom%hrbuf_up, n, MPI_INTEGER2, dom%below, TAG_UP, dom%comm, dom%req(1))
      call MPI_Irecv(dom%hrbuf_dn, n, MPI_INTEGER2, dom%above, TAG_DOWN, dom%comm, dom%req(2))
      do k = 1, 3
        dom%hbuf_up((k - 1)*nx + 1:k*nx) = f%h(1:nx, dom%nyl, up_pops(k))
        dom%hbuf_dn((k - 1)*nx + 1:k*nx) = f%h(1:nx, 1, down_pops(k))
      end do
      call MPI_Isend(dom%hbuf_up, n, MPI_INTEGER2, dom%above, TAG_UP, dom%comm, dom%req(3))
      call MPI_Isend(dom%hbuf_dn, n, MPI_INTEGER2, dom%below, TAG_DOWN, dom%comm, dom%req(4))
      return
    end if
    call MPI_Irecv(dom%rbuf_up, n, mpi_wp, dom%below, TAG_UP, dom%comm, dom%req(1))
    call MPI_Irecv(dom%rbuf_dn, n, mpi_wp, dom%above, TAG_DOWN, dom%comm, dom%req(2))
    do k = 1, 3
      if (f%single) then
        dom%sbuf_up((k - 1)*nx + 1:k*nx) = real(f%s(1:nx, dom%nyl, up_pops(k)), wp)
        dom%sbuf_dn((k - 1)*nx + 1:k*nx) = real(f%s(1:nx, 1, down_pops(k)), wp)
      else
        dom%sbuf_up((k - 1)*nx + 1:k*nx) = f%d(1:nx, dom%nyl, up_pops(k))
        dom%sbuf_dn((k - 1)*nx + 1:k*nx) = f%d(1:nx, 1, down_pops(k))
      end if
    end do
    call MPI_Isend(dom%sbuf_up, n, mpi_wp, dom%above, TAG_UP, dom%comm, dom%req(3))
    call MPI_Isend(dom%sbuf_dn, n, mpi_wp, dom%below, TAG_DOWN, dom%comm, dom%req(4))
  end subroutine halo_start

  !> Complete the exchange started by halo_start and unpack into the halo rows.
  subroutine halo_finish(dom, f)
    type(domain_t), intent(inout) :: dom
    type(lattice_t), intent(inout) :: f
    integer :: k, nx
    nx = dom%nx
    call wait_start()
    call MPI_Waitall(4, dom%req, MPI_STATUSES_IGNORE)
    call wait_stop()
    if (dom%below /= MPI_PROC_NULL) then
      do k = 1, 3
        if (f%half) then
          f%h(1:nx, 0, up_pops(k)) = dom%hrbuf_up((k - 1)*nx + 1:k*nx)
        else if (f%single) then
          f%s(1:nx, 0, up_pops(k)) = real(dom%rbuf_up((k - 1)*nx + 1:k*nx), sp)
        else
          f%d(1:nx, 0, up_pops(k)) = dom%rbuf_up((k - 1)*nx + 1:k*nx)
        end if
      end do
    end if
    if (dom%above /= MPI_PROC_NULL) then
      do k = 1, 3
        if (f%half) then
          f%h(1:nx, dom%nyl + 1, down_pops(k)) = dom%hrbuf_dn((k - 1)*nx + 1:k*nx)
        else if (f%single) then
          f%s(1:nx, dom%nyl + 1, down_pops(k)) = real(dom%rbuf_dn((k - 1)*nx + 1:k*nx), sp)
        else
          f%d(1:nx, dom%nyl + 1, down_pops(k)) = dom%rbuf_dn((k - 1)*nx + 1:k*nx)
        end if
      end do
    end if
  end subroutine halo_finish

  !> One value per column of the two edge rows to the neighbours: `first` (row 1) goes to the
  !! lower neighbour, `last` (row nyl) to the upper one; `below` receives the lower neighbour's
  !! row nyl (this slab's halo row 0), `above` the upper neighbour's row 1 (halo row nyl+1).
  !! At a closed or open end the receiving array is left as it is. The values travel unchanged,
  !! so a halo value has the bits its owner computed.
  subroutine domain_edge_rows(dom, first, last, below, above)
    type(domain_t), intent(in) :: dom
    real(wp), intent(in) :: first(:), last(:)
    real(wp), intent(inout) :: below(:), above(:)
    call MPI_Sendrecv(last, size(last), mpi_wp, dom%above, TAG_EDGE_UP, below, size(below), &
                      mpi_wp, dom%below, TAG_EDGE_UP, dom%comm, MPI_STATUS_IGNORE)
    call MPI_Sendrecv(first, size(first), mpi_wp, dom%below, TAG_EDGE_DOWN, above, &
                      size(above), mpi_wp, dom%above, TAG_EDGE_DOWN, dom%comm, MPI_STATUS_IGNORE)
  end subroutine domain_edge_rows

end module dkt_domain

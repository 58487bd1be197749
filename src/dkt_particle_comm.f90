!> The particles' messages (docs/design.md, "Particles across slabs"), apart from their physics:
!> the two neighbouring slabs, the send and receive buffers of the messages between them, the
!> few collectives the particles need (a minimum, agreeing on one failure, a gather of every
!> disk for output), and the counters of what was sent. The only particle module that uses MPI.
!>
!> A message between neighbours is a list of items of `unit` numbers each: the sender appends
!> items for the slab below or above (comm_put), comm_swap sends both lists and receives the
!> neighbours' lists in their order, and the receiver reads item b of either (comm_item).
module dkt_particle_comm
  use mpi_f08, only: MPI_Comm, MPI_Isend, MPI_Probe, MPI_Get_count, MPI_Recv, MPI_Waitall, &
                     MPI_Request, MPI_Status, MPI_Allgather, MPI_Allgatherv, MPI_Allreduce, &
                     MPI_Bcast, MPI_STATUS_IGNORE, MPI_STATUSES_IGNORE, MPI_INTEGER, &
                     MPI_CHARACTER, MPI_MIN, MPI_IN_PLACE, MPI_PROC_NULL
  use dkt_kinds, only: wp, mpi_wp, i8
  use dkt_domain, only: domain_t
  use dkt_particle_state, only: fit_real
  use dkt_timers, only: wait_start, wait_stop
  implicit none
  private
  public :: particle_comm_t, comm_init, comm_start, comm_put, comm_swap, comm_item, comm_id, &
            comm_min, comm_min_int, comm_agree, comm_allgather, comm_messages, comm_bytes, &
            SLAB_BELOW, SLAB_ABOVE

  integer, parameter :: TAG_DOWN = 42, TAG_UP = 43
  integer, parameter :: WP_BYTES = storage_size(1.0_wp)/8 !! bytes of a number in a message
  !> which neighbour a received item came from (comm_item), or a sent one goes to (comm_put)
  integer, parameter :: SLAB_BELOW = 1, SLAB_ABOVE = 2

  !> One slab's particle messages: its neighbours, the buffers (grown as needed, never shrunk:
  !! no allocation in most steps) and the counts of the present message, and the counters.
  type :: particle_comm_t
    private
    type(MPI_Comm) :: comm
    integer :: rank = 0, nranks = 1
    integer :: below = MPI_PROC_NULL, above = MPI_PROC_NULL !! the neighbouring slabs' ranks
    integer :: unit = 1                  !! numbers per item of the present message
    integer :: nd = 0, nu = 0            !! items to send down, up
    integer :: md = 0, mu = 0            !! items received from below, from above
    real(wp), allocatable :: sdn(:), sup(:), rdn(:), rup(:)
    !> MPI calls made: to neighbours, and collectives
    integer(i8) :: neighbour_calls = 0, collective_calls = 0
    integer(i8) :: neighbour_bytes = 0   !! bytes sent to neighbours
  end type particle_comm_t

contains

  !> The messages of the slab `dom`: its communicator and neighbours (which a window's growth
  !! keeps: it splits the rows anew over the same ranks).
  subroutine comm_init(c, dom)
    type(particle_comm_t), intent(out) :: c
    type(domain_t), intent(in) :: dom
    c%comm = dom%comm
    c%rank = dom%rank
    c%nranks = dom%nranks
    c%below = dom%below
    c%above = dom%above
    allocate (c%sdn(0), c%sup(0), c%rdn(0), c%rup(0))
  end subroutine comm_init

  !> Begin a message of items of `unit` numbers: nothing to send yet.
  pure subroutine comm_start(c, unit)
    type(particle_comm_t), intent(inout) :: c
    integer, intent(in) :: unit
    c%unit = unit
    c%nd = 0
    c%nu = 0
  end subroutine comm_start

  !> Append the item v (`unit` numbers) to the list for the slab below (SLAB_BELOW: the side it
  !! goes to) or above (SLAB_ABOVE).
  subroutine comm_put(c, side, v)
    type(particle_comm_t), intent(inout) :: c
    integer, intent(in) :: side
    real(wp), intent(in) :: v(:)
    if (side == SLAB_BELOW) then
      call fit_real(c%sdn, c%unit*(c%nd + 1))
      c%sdn(c%unit*c%nd + 1:c%unit*(c%nd + 1)) = v
      c%nd = c%nd + 1
    else
      call fit_real(c%sup, c%unit*(c%nu + 1))
      c%sup(c%unit*c%nu + 1:c%unit*(c%nu + 1)) = v
      c%nu = c%nu + 1
    end if
  end subroutine comm_put

  !> Send the items put for the slab below and above; receive md items from below and mu from
  !! above (0 at a closed or open end). One message each way: the receiver learns its length
  !! from the message (MPI_Probe), so no count travels first.
  subroutine comm_swap(c, md, mu)
    type(particle_comm_t), intent(inout) :: c
    integer, intent(out) :: md, mu
    type(MPI_Request) :: req(2)
    type(MPI_Status) :: st
    integer :: n
    ! the messages, one each way (counted at an end too, where none travels: the count per step
    ! is the scheme's, on any number of ranks), and the bytes that travel
    c%neighbour_calls = c%neighbour_calls + 2
    if (c%below /= MPI_PROC_NULL) c%neighbour_bytes = c%neighbour_bytes + c%unit*c%nd*WP_BYTES
    if (c%above /= MPI_PROC_NULL) c%neighbour_bytes = c%neighbour_bytes + c%unit*c%nu*WP_BYTES
    c%md = 0
    c%mu = 0
    ! a slab with no neighbour either way (one rank, closed or open ends): nothing to send
    if (c%below /= MPI_PROC_NULL .or. c%above /= MPI_PROC_NULL) then
      call MPI_Isend(c%sdn, c%unit*c%nd, mpi_wp, c%below, TAG_DOWN, c%comm, req(1))
      call MPI_Isend(c%sup, c%unit*c%nu, mpi_wp, c%above, TAG_UP, c%comm, req(2))
      ! from above what it sent down, from below what it sent up (the time it takes them to
      ! come is the wait for the neighbours)
      call wait_start()
      call MPI_Probe(c%above, TAG_DOWN, c%comm, st)
      call MPI_Get_count(st, mpi_wp, n)
      c%mu = n/c%unit
      call fit_real(c%rup, n)
      call MPI_Recv(c%rup, n, mpi_wp, c%above, TAG_DOWN, c%comm, MPI_STATUS_IGNORE)
      call MPI_Probe(c%below, TAG_UP, c%comm, st)
      call MPI_Get_count(st, mpi_wp, n)
      c%md = n/c%unit
      call fit_real(c%rdn, n)
      call MPI_Recv(c%rdn, n, mpi_wp, c%below, TAG_UP, c%comm, MPI_STATUS_IGNORE)
      call MPI_Waitall(2, req, MPI_STATUSES_IGNORE)
      call wait_stop()
    end if
    md = c%md
    mu = c%mu
  end subroutine comm_swap

  !> Item b (1..md or 1..mu) received from below (SLAB_BELOW) or above (SLAB_ABOVE).
  pure function comm_item(c, side, b) result(v)
    type(particle_comm_t), intent(in) :: c
    integer, intent(in) :: side, b
    real(wp) :: v(c%unit)
    if (side == SLAB_BELOW) then
      v = c%rdn(c%unit*(b - 1) + 1:c%unit*b)
    else
      v = c%rup(c%unit*(b - 1) + 1:c%unit*b)
    end if
  end function comm_item

  !> The first number of item b received from `side` as an integer (the items' keys: a disk's id)
  pure integer function comm_id(c, side, b) result(id)
    type(particle_comm_t), intent(in) :: c
    integer, intent(in) :: side, b
    if (side == SLAB_BELOW) then
      id = nint(c%rdn(c%unit*(b - 1) + 1))
    else
      id = nint(c%rup(c%unit*(b - 1) + 1))
    end if
  end function comm_id

  !> The element-wise minimum of v over the ranks, in place.
  subroutine comm_min(c, v)
    type(particle_comm_t), intent(inout) :: c
    real(wp), intent(inout) :: v(:)
    call wait_start()
    call MPI_Allreduce(MPI_IN_PLACE, v, size(v), mpi_wp, MPI_MIN, c%comm)
    call wait_stop()
    c%collective_calls = c%collective_calls + 1
  end subroutine comm_min

  !> The minimum of i over the ranks.
  integer function comm_min_int(c, i) result(least)
    type(particle_comm_t), intent(inout) :: c
    integer, intent(in) :: i
    call wait_start()
    call MPI_Allreduce(i, least, 1, MPI_INTEGER, MPI_MIN, c%comm)
    call wait_stop()
    c%collective_calls = c%collective_calls + 1
  end function comm_min_int

  !> Agree on a failure found by some ranks: the one with the lowest key (a particle's id;
  !! huge(0) for none) sends its message to every rank. `msg` is then the same everywhere.
  !! `lowest`, when given, is the lowest key over the ranks, already reduced (comm_min).
  subroutine comm_agree(c, key, msg, lowest)
    type(particle_comm_t), intent(inout) :: c
    integer, intent(in) :: key
    character(len=:), allocatable, intent(inout) :: msg
    integer, intent(in), optional :: lowest
    integer :: pair(2), least(2), n
    pair = [key, c%rank]
    ! the lowest key, and of the ranks that have it the lowest
    if (present(lowest)) then
      least(1) = lowest
    else
      least(1) = comm_min_int(c, pair(1))
    end if
    if (least(1) == huge(0)) then
      msg = ''
      return
    end if
    if (key /= least(1)) pair(2) = huge(0)
    call MPI_Allreduce(pair(2), least(2), 1, MPI_INTEGER, MPI_MIN, c%comm)
    n = 0
    if (c%rank == least(2)) n = len(msg)
    call MPI_Bcast(n, 1, MPI_INTEGER, least(2), c%comm)
    if (c%rank /= least(2)) then
      deallocate (msg)
      allocate (character(len=n) :: msg)
    end if
    call MPI_Bcast(msg, n, MPI_CHARACTER, least(2), c%comm)
    c%collective_calls = c%collective_calls + 3
  end subroutine comm_agree

  !> Every rank's `mine`, in rank order, on every rank (output, checkpoints, a window that
  !! grows; not in the time loop's steps).
  subroutine comm_allgather(c, mine, every)
    type(particle_comm_t), intent(in) :: c
    real(wp), intent(in) :: mine(:)
    real(wp), allocatable, intent(out) :: every(:)
    integer :: counts(c%nranks), displs(c%nranks), r
    call MPI_Allgather(size(mine), 1, MPI_INTEGER, counts, 1, MPI_INTEGER, c%comm)
    displs(1) = 0
    do r = 2, c%nranks
      displs(r) = displs(r - 1) + counts(r - 1)
    end do
    allocate (every(sum(counts)))
    call MPI_Allgatherv(mine, size(mine), mpi_wp, every, counts, displs, mpi_wp, c%comm)
  end subroutine comm_allgather

  !> The MPI calls made so far: to neighbours, and collectives.
  pure function comm_messages(c) result(calls)
    type(particle_comm_t), intent(in) :: c
    integer(i8) :: calls(2)
    calls = [c%neighbour_calls, c%collective_calls]
  end function comm_messages

  !> The bytes sent to neighbours so far.
  pure integer(i8) function comm_bytes(c)
    type(particle_comm_t), intent(in) :: c
    comm_bytes = c%neighbour_bytes
  end function comm_bytes
end module dkt_particle_comm

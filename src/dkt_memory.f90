!> The memory one rank needs for its slab (one formula for the start-up report and the check)
!> and the check that the ranks of one node fit in what the node gives, made before anything
!> large is allocated.
module dkt_memory
  use mpi_f08, only: MPI_Comm, MPI_Bcast, MPI_Comm_size, MPI_INTEGER, MPI_Allreduce, MPI_MAX, &
                     MPI_Comm_split_type, MPI_COMM_TYPE_SHARED, MPI_INFO_NULL, MPI_Comm_free, &
                     MPI_IN_PLACE
  use dkt_kinds, only: wp, pi, mpi_wp
  use dkt_errors, only: fatal_all
  use dkt_config, only: config_t, lattice_params_t
  use dkt_domain, only: domain_t
  use dkt_text, only: fmt_real, counted
  use dkt_store, only: lattice_bytes
  use dkt_choices, only: STREAMING_IN_PLACE
  implicit none
  private
  public :: rank_memory, check_memory, fixed2, GIB, MIB

  real(wp), parameter :: GIB = 2.0_wp**30, MIB = 2.0_wp**20

  !> doubles per column in the row buffers of the sweep (dkt_mrt sweep_t: below, saved, o13,
  !! kept_dn, kept_up in either storage, and the room for a row)
  real(wp), parameter :: SWEEP_ROW_DOUBLES = 3.0_wp + 3.0_wp + 2.0_wp + 3.0_wp + 9.0_wp + 4.5_wp + &
                         9.0_wp + 4.5_wp
  !> bytes of a boundary link (dkt_particles): particle, column, row, direction, row entry and
  !! second-node flag (4 each), q (8), its place in the row order (4), and the copy of column,
  !! row, direction, row entry and flag the link search keeps for the next step (4 each)
  real(wp), parameter :: LINK_BYTES = 6*4 + 8 + 4 + 5*4

contains

  !> Bytes one rank needs for its slab, the one formula behind the start-up report and the
  !! memory check: (1) the lattice (one with lbm.streaming = 'in_place', two otherwise), 9
  !! populations per padded node (nxp columns, nyl rows and two halo rows) of 8 bytes, or 4 with
  !! lbm.precision = 'single' or 'single_arith', or 2 with 'half';
  !! (2) the particles, counted as if the slab held all of them (a slab holds its own and the
  !! ghosts within reach, and every rank reads the whole scene): per particle its state three
  !! times over (held, before the move, the merge of a message; 128 bytes each) and two message
  !! slots (16 doubles each), the boundary links, at most 8 per surface node and about pi d + 8
  !! surface nodes per particle of d spacings (56 bytes a link: its record, its place in the
  !! row order and the copy the search keeps), and per row it spans (d + 4 rows) the force sums
  !! and the runs of its nodes now and before the move (56 bytes); and the mask of the nodes
  !! inside disks (a 4-byte logical per node of the slab and the rows beside it); (3) the
  !! output: the field buffer of up to 6 doubles per node, the halo send and receive buffers (12
  !! doubles per column) and the row buffers of the sweep (SWEEP_ROW_DOUBLES per padded column).
  pure function rank_memory(cfg, lp, nxp, nyl) result(bytes)
    type(config_t), intent(in) :: cfg
    type(lattice_params_t), intent(in) :: lp
    integer, intent(in) :: nxp, nyl
    real(wp) :: bytes(3)
    real(wp) :: d_cells
    integer :: n
    bytes(1) = merge(1.0_wp, 2.0_wp, cfg%lbm%streaming_kind == STREAMING_IN_PLACE)*9.0_wp* &
               real(lattice_bytes(cfg%lbm%precision_kind), wp)*real(nxp, wp)*real(nyl + 2, wp)
    n = cfg%particles%count
    bytes(2) = 0.0_wp
    if (n > 0) then
      d_cells = lp%largest_diameter/lp%dx
      bytes(2) = real(n, wp)*(3.0_wp*128.0_wp + 2.0_wp*16.0_wp*8.0_wp + &
                              LINK_BYTES*8.0_wp*(pi*d_cells + 8.0_wp) + &
                              56.0_wp*(d_cells + 4.0_wp)) + &
                 4.0_wp*real(lp%nx, wp)*real(nyl + 2, wp)
    end if
    bytes(3) = 6.0_wp*8.0_wp*real(lp%nx, wp)*real(nyl, wp) + 12.0_wp*8.0_wp*real(lp%nx, wp) + &
               SWEEP_ROW_DOUBLES*8.0_wp*real(nxp, wp)
  end function rank_memory

  !> Stop every rank before the lattices are allocated when the ranks of one node would need
  !! more than it gives: run.memory_limit GiB, or (0) MemAvailable of /proc/meminfo on rank 0's
  !! node. A node holds at most the largest count of ranks sharing one node; each rank is
  !! counted with the largest slab. Without /proc/meminfo and with no limit, nothing is checked.
  subroutine check_memory(cfg, lp, dom)
    type(config_t), intent(in) :: cfg
    type(lattice_params_t), intent(in) :: lp
    type(domain_t), intent(in) :: dom
    type(MPI_Comm) :: node
    real(wp) :: bytes(3), need, avail, limit
    integer :: node_ranks
    character(len=:), allocatable :: source, limit_text
    character(len=160) :: msg
    bytes = rank_memory(cfg, lp, dom%nxp, dom%nyl)
    call MPI_Allreduce(MPI_IN_PLACE, bytes, 3, mpi_wp, MPI_MAX, dom%comm)
    call MPI_Comm_split_type(dom%comm, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, node)
    call MPI_Comm_size(node, node_ranks)
    call MPI_Comm_free(node)
    call MPI_Allreduce(MPI_IN_PLACE, node_ranks, 1, MPI_INTEGER, MPI_MAX, dom%comm)
    avail = -1.0_wp
    if (dom%rank == 0) avail = mem_available()
    call MPI_Bcast(avail, 1, mpi_wp, 0, dom%comm)
    if (cfg%run%memory_limit > 0.0_wp) then
      limit = cfg%run%memory_limit*GIB
      source = 'run.memory_limit'
      limit_text = fmt_real(cfg%run%memory_limit) ! as the user gave it
    else
      limit = avail
      source = 'MemAvailable in /proc/meminfo'
      limit_text = gib_text(limit/GIB)
    end if
    need = real(node_ranks, wp)*sum(bytes)
    if (limit < 0.0_wp .or. need <= limit) return
    write (msg, '(a,i0,a,i0,a)') ' for ', lp%nx, ' x ', dom%ny, &
      ' cells, times '//counted(node_ranks, 'rank')//' on a node = '
    call fatal_all(trim(cfg%file)//': the run needs '//gib_text(sum(bytes)/GIB, up=.true.)// &
                   ' GiB per rank (lattices '//gib_text(bytes(1)/GIB)//' GiB, particle '// &
                   'arrays '//gib_text(bytes(2)/GIB)//' GiB, output buffers '// &
                   gib_text(bytes(3)/GIB)//' GiB)'//trim(msg)//' '// &
                   gib_text(need/GIB, up=.true.)//' GiB, more than the '//limit_text// &
                   ' GiB allowed ('//source//'); use fewer '// &
                   'cells: a larger lbm.dx, a smaller lbm.cells_per_diameter (it sets dx '// &
                   'from the smallest particle; with &pair a smaller gamma) or a smaller '// &
                   '&domain; or spread the ranks over more nodes; or set run.memory_limit '// &
                   '(GiB) to what the run may really use')
  end subroutine check_memory

  !> A size in GiB as text with three significant digits ('0.0512', '335.0', '1.2e-6'), at
  !! least to two decimals: a small need or limit (run.memory_limit = 1e-6) would otherwise
  !! print as 0.0 and the message 'needs 0.0 GiB, more than the 0.0 GiB allowed'. With `up`
  !! rounded up, so that a need printed is never below the need.
  function gib_text(x, up) result(s)
    real(wp), intent(in) :: x
    logical, intent(in), optional :: up
    character(len=:), allocatable :: s
    character(len=16) :: buf
    real(wp) :: scale, y
    scale = 100.0_wp
    if (abs(x) > 0.0_wp .and. abs(x) < 100.0_wp) scale = 10.0_wp**(2 - floor(log10(abs(x))))
    y = anint(x*scale)
    if (present(up)) then
      if (up) y = ceiling(x*scale)
    end if
    y = y/scale
    if (scale > 100.0_wp) then ! three digits: read back, to drop the noise of the division
      write (buf, '(es16.2e3)') y
      read (buf, *) y
    end if
    s = fmt_real(y)
  end function gib_text

  !> x rounded to two decimals, as text ('0.05', '335.32')
  function fixed2(x) result(s)
    real(wp), intent(in) :: x
    character(len=:), allocatable :: s
    s = fmt_real(anint(x*100.0_wp)/100.0_wp)
  end function fixed2

  !> MemAvailable of /proc/meminfo in bytes; -1 where it cannot be read.
  function mem_available() result(bytes)
    real(wp) :: bytes
    character(len=256) :: line
    integer :: u, ios
    real(wp) :: kib
    bytes = -1.0_wp
    open (newunit=u, file='/proc/meminfo', status='old', action='read', iostat=ios)
    if (ios /= 0) return
    do
      read (u, '(a)', iostat=ios) line
      if (ios /= 0) exit
      if (index(line, 'MemAvailable:') == 1) then
        read (line(14:), *, iostat=ios) kib
        if (ios == 0) bytes = kib*1024.0_wp
        exit
      end if
    end do
    close (u)
  end function mem_available

end module dkt_memory

!> The link search through the cell list (dkt_cells) finds what a search over every disk finds.
!>  - links_find on a crowd of 150 disks of radius 1.5..3.5 dropped at random into a
!>    60 x 90 closed channel (many overlapping, some across a side or an end), with interior
!>    links (coupling.interior = 'fluid'): the boundary links (particle, column, row, direction,
!>    second fluid node) and the interior links (particle, node, direction, fluid neighbour) are
!>    those, in that order, of a loop that tests every node against every disk.
!>  - the crowd does test the cells: some nodes lie in two disks, and a query around a node
!>    returns a small part of the crowd.
!> Run on 1 and 2 ranks: each rank checks the links of its own slab.
program test_cells
  use mpi_f08, only: MPI_Init, MPI_Finalize, MPI_COMM_WORLD
  use dkt_kinds, only: wp
  use dkt_check, only: check, finish
  use dkt_lattice, only: ex, ey
  use dkt_domain, only: domain_t, domain_init
  use dkt_choices, only: BB_YU
  use dkt_particles, only: particles_t, particles_init, MOTION_FREE
  use dkt_links, only: links_t, links_init, links_find, links_count, links_table, links_inner_table
  use dkt_cells, only: cells_t, cells_build, cells_near
  implicit none
  integer, parameter :: n = 150, nx = 60, ny = 90
  type(domain_t) :: dom
  type(particles_t) :: ps
  type(links_t) :: lk
  character(len=:), allocatable :: err
  real(wp) :: px(n), py(n), pr(n), zero(n)
  integer, allocatable :: want(:, :), want_inner(:, :), got(:, :), got_inner(:, :)
  integer :: k

  call MPI_Init()
  ! the same crowd on every rank: a fixed scattered sequence, not each process's random numbers
  px = [(modulo(37.0_wp*k*0.6180339887_wp, 1.0_wp), k=1, n)]
  py = [(modulo(53.0_wp*k*0.4142135623_wp, 1.0_wp), k=1, n)]
  pr = [(modulo(11.0_wp*k*0.7320508075_wp, 1.0_wp), k=1, n)]
  px = nx*px
  py = ny*py
  pr = 1.5_wp + 2.0_wp*pr
  zero = 0.0_wp
  call domain_init(dom, MPI_COMM_WORLD, nx, ny, .false., .false., 1, err)
  if (len(err) > 0) error stop err
  call particles_init(ps, dom, px, py, pr, zero, zero, zero, [(1.5_wp, k=1, n)], &
                      [(MOTION_FREE, k=1, n)], 1.0e-5_wp, 1.0_wp, 1.0_wp, 1.0_wp, 1)
  call links_init(lk, dom, BB_YU, .false., .true.)
  call links_find(lk, ps, dom)
  call search_all(want, want_inner)

  ! (links name the particles a slab holds by their place there; the table, by their number)
  got = links_table(lk)
  got(1, :) = ps%p%id(got(1, :))
  got_inner = links_inner_table(lk)
  got_inner(1, :) = ps%p%id(got_inner(1, :))
  call check('cells: the boundary links of a search over every disk, in its order', &
             same(got, want), real(size(got, 2) - size(want, 2), wp))
  call check('cells: the interior links of a search over every disk, in its order', &
             same(got_inner, want_inner), real(size(got_inner, 2) - size(want_inner, 2), wp))
  call check('cells: the crowd has links', links_count(lk) > 100, real(links_count(lk), wp))
  call check('cells: some nodes lie in two disks', in_two() > 0, real(in_two(), wp))
  call check('cells: a query returns a small part of the crowd', query_size() < n/5, &
             real(query_size(), wp))
  call finish()
  call MPI_Finalize()

contains

  logical function inside(k, x, y)
    integer, intent(in) :: k
    real(wp), intent(in) :: x, y
    inside = (x - px(k))**2 + (y - py(k))**2 < pr(k)**2
  end function inside

  !> A node of the channel outside every disk, testing all of them.
  logical function fluid(i, jg)
    integer, intent(in) :: i, jg
    fluid = i >= 1 .and. i <= nx .and. jg >= 1 .and. jg <= ny
    if (fluid) fluid = .not. any([(inside(k, i - 0.5_wp, jg - 0.5_wp), k=1, n)])
  end function fluid

  !> The links of this slab found the plain way, in the order particle, row, column, direction:
  !! links(:, l) = (particle, column, local row, direction, second node fluid), and the
  !! interior links (particle, column, local row, direction, neighbour fluid).
  subroutine search_all(links, inner)
    integer, allocatable, intent(out) :: links(:, :), inner(:, :)
    integer :: k, i, j, jg, d, i1, i2, j1, j2
    allocate (links(5, 0), inner(5, 0))
    do k = 1, n
      ! the rows and columns dkt_particles scans: the disk's box with a margin of two nodes
      i1 = max(1, floor(px(k) - pr(k)) - 2)
      i2 = min(dom%nx, ceiling(px(k) + pr(k)) + 2)
      j1 = max(1, floor(py(k) - pr(k)) - 2 - dom%y0)
      j2 = min(dom%nyl, ceiling(py(k) + pr(k)) + 2 - dom%y0)
      do j = j1, j2
        jg = dom%y0 + j
        do i = i1, i2
          if (.not. fluid(i, jg)) then
            if (.not. inside(k, i - 0.5_wp, jg - 0.5_wp)) cycle
            do d = 1, 8
              if (inside(k, i - ex(d) - 0.5_wp, jg - ey(d) - 0.5_wp)) cycle
              if (i - ex(d) < 1 .or. i - ex(d) > nx .or. jg - ey(d) < 1 .or. jg - ey(d) > ny) &
                cycle
              inner = reshape([inner, [k, i, j, d, merge(1, 0, fluid(i - ex(d), jg - ey(d)))]], &
                              [5, size(inner, 2) + 1])
            end do
            cycle
          end if
          do d = 1, 8
            if (.not. inside(k, i - 0.5_wp + ex(d), jg - 0.5_wp + ey(d))) cycle
            links = reshape([links, [k, i, j, d, merge(1, 0, fluid(i - ex(d), jg - ey(d)))]], &
                            [5, size(links, 2) + 1])
          end do
        end do
      end do
    end do
  end subroutine search_all

  !> Two tables of links are the same, row for row.
  pure logical function same(got, wanted)
    integer, intent(in) :: got(:, :), wanted(:, :)
    same = size(got, 2) == size(wanted, 2)
    if (same) same = all(got == wanted)
  end function same

  !> Nodes of the channel inside two disks or more.
  integer function in_two()
    integer :: i, jg
    in_two = 0
    do jg = 1, ny
      do i = 1, nx
        if (count([(inside(k, i - 0.5_wp, jg - 0.5_wp), k=1, n)]) > 1) in_two = in_two + 1
      end do
    end do
  end function in_two

  !> The disks the cells return around the middle of the channel, within the largest radius.
  integer function query_size()
    type(cells_t) :: c
    integer, allocatable :: near(:)
    integer :: m
    call cells_build(c, px, py, 2.0_wp*maxval(pr))
    call cells_near(c, 0.5_wp*nx, 0.5_wp*ny, maxval(pr), near, m)
    query_size = m
  end function query_size

end program test_cells

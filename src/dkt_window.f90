!> The moving window of an infinite channel (docs/model.md §5): the lattice follows the lowest free
!> particle down. Each time that particle has moved down by one lattice spacing, the top row
!> of the lattice is dropped, every row moves up by one, and a fresh row of fluid at rest
!> (equilibrium) enters at the bottom; the particles move up by one spacing in lattice
!> coordinates, so their absolute positions are unchanged.
!>
!> Across slabs the shift is one exchange: each rank sends its top row (all nine populations)
!> to the rank above and receives the top row of the rank below as its new first row. A shift
!> is exact (a copy of values; particle coordinates move by 1.0, which is exact in floating
!> point for coordinates >= 1), and every rank decides it from the same particle state, so a
!> window run has the same bits on any number of ranks.
module dkt_window
  use mpi_f08, only: MPI_Sendrecv, MPI_STATUS_IGNORE
  use iso_fortran_env, only: int16
  use dkt_kinds, only: wp, sp, mpi_wp
  use dkt_lattice, only: equilibrium
  use dkt_domain, only: domain_t
  use dkt_store, only: lattice_t, lattice_set_node
  use dkt_particles, only: particles_t, particles_lowest_free, particles_first_above
  implicit none
  private
  public :: window_t, window_init, window_offset, window_follow, window_escaped, &
            window_escape_line

  integer, parameter :: TAG_SHIFT = 21

  abstract interface
    !> What the caller does once before the first row moves (window_follow)
    subroutine before_shift_i()
    end subroutine before_shift_i
  end interface

  type :: window_t
    integer :: shift = 0            !! rows the window has moved down since t = 0
    real(wp) :: y_origin = 0.0_wp   !! cm, absolute y of the lower end at t = 0
    real(wp) :: below = 0.0_wp      !! lattice spacings from the lower end to the lowest centre
    real(wp) :: margin = 0.0_wp     !! lattice spacings: the closest a particle may come to the top
  end type window_t

contains

  !> A window whose lower end starts at y_origin (cm), keeping the lowest free centre `below`
  !! spacings above it; a particle within `margin` spacings of the upper end has escaped.
  subroutine window_init(win, y_origin, below, margin)
    type(window_t), intent(out) :: win
    real(wp), intent(in) :: y_origin, below, margin
    win%y_origin = y_origin
    win%below = below
    win%margin = margin
  end subroutine window_init

  !> y (cm, absolute) of the window's lower end, the y of the bottom face of row 1.
  pure real(wp) function window_offset(win, dx) result(y)
    type(window_t), intent(in) :: win
    real(wp), intent(in) :: dx !! cm, lattice spacing
    y = win%y_origin - real(win%shift, wp)*dx
  end function window_offset

  !> Move the window down, a row at a time, until the lowest free particle is again within one
  !! spacing of `below` above the lower end. f holds the populations of rows 1..nyl between
  !! two steps; the caller finds the boundary links after it.
  !!
  !! The loop depends on the particle state, so it is bounded: a position that is not finite
  !! (a flow gone NaN) moves nothing, and the window moves at most ny rows in a call (a particle
  !! moves less than a spacing a step, run.particle_speed_limit); a particle left below the
  !! lower end then stops the run (the caller's place check). `before_shift`, when given, is
  !! called once before the first row moves (and not at all in a step that moves none).
  subroutine window_follow(win, dom, ps, f, before_shift)
    type(window_t), intent(inout) :: win
    type(domain_t), intent(in) :: dom
    type(particles_t), intent(inout) :: ps
    type(lattice_t), intent(inout) :: f
    procedure(before_shift_i), optional :: before_shift
    real(wp) :: lowest
    logical :: finite
    integer :: k, rows
    do rows = 1, dom%ny
      ! over every slab's own free particles (one reduction)
      call particles_lowest_free(ps, dom, lowest, finite)
      if (.not. finite) return
      if (lowest >= win%below - 1.0_wp) exit
      if (rows == 1 .and. present(before_shift)) call before_shift()
      call shift_rows(dom, f)
      do k = 1, ps%n
        ps%p%y(k) = ps%p%y(k) + 1.0_wp
      end do
      win%shift = win%shift + 1
    end do
  end subroutine window_follow

  !> The first particle (by number) within the margin of the window's upper end, 0 if none:
  !! the pair has separated by more than the window holds. Every rank calls it.
  integer function window_escaped(win, dom, ps, ny) result(k)
    type(window_t), intent(in) :: win
    type(domain_t), intent(in) :: dom
    type(particles_t), intent(inout) :: ps
    integer, intent(in) :: ny !! rows of the lattice
    k = particles_first_above(ps, dom, window_escape_line(win, ny))
  end function window_escaped

  !> The height (lattice units) above which a disk's top has escaped a window of ny rows.
  pure real(wp) function window_escape_line(win, ny) result(top)
    type(window_t), intent(in) :: win
    integer, intent(in) :: ny
    top = real(ny, wp) - win%margin
  end function window_escape_line

  !> Every row moves up by one: the top row of each slab goes to the slab above (the top row of
  !! the channel is dropped), and the bottom slab gets a fresh row of fluid at rest. The message
  !! holds columns 0..nx+1 of the nine populations, a size both sides compute from nx: the
  !! padding beyond nx+1 is never sent. The stored values move as they are (4-byte values and
  !! 16-bit codes travel exactly in the 8-byte buffer); the entering row is set from its 8-byte
  !! equilibrium.
  subroutine shift_rows(dom, f)
    type(domain_t), intent(in) :: dom
    type(lattice_t), intent(inout) :: f
    real(wp), allocatable :: sbuf(:, :), rbuf(:, :)
    real(wp) :: feq(0:8)
    integer :: j, i, nyl, last
    nyl = dom%nyl
    last = dom%nx + 1
    allocate (sbuf(0:last, 0:8), rbuf(0:last, 0:8))
    if (f%half) then
      sbuf = real(f%h(0:last, nyl, :), wp)
    else if (f%single) then
      sbuf = real(f%s(0:last, nyl, :), wp)
    else
      sbuf = f%d(0:last, nyl, :)
    end if
    call MPI_Sendrecv(sbuf, size(sbuf), mpi_wp, dom%above, TAG_SHIFT, rbuf, size(rbuf), mpi_wp, &
                      dom%below, TAG_SHIFT, dom%comm, MPI_STATUS_IGNORE)
    do j = nyl, 2, -1
      if (f%half) then
        f%h(0:last, j, :) = f%h(0:last, j - 1, :)
      else if (f%single) then
        f%s(0:last, j, :) = f%s(0:last, j - 1, :)
      else
        f%d(0:last, j, :) = f%d(0:last, j - 1, :)
      end if
    end do
    if (dom%has_lower_end) then
      feq = equilibrium(1.0_wp, 0.0_wp, 0.0_wp)
      do i = 0, last
        call lattice_set_node(f, i, 1, feq)
      end do
    else if (f%half) then
      f%h(0:last, 1, :) = int(rbuf, int16)
    else if (f%single) then
      f%s(0:last, 1, :) = real(rbuf, sp)
    else
      f%d(0:last, 1, :) = rbuf
    end if
  end subroutine shift_rows

end module dkt_window

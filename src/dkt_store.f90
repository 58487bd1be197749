!> Storage of a lattice of populations (docs/design.md, "Data layout"): f(0:nxp-1, 0:nyl+1, 0:8)
!> in 8 bytes (lbm.precision = 'double', the default), in 4 bytes ('single', 'single_arith') or
!> in 2 ('half').
!>
!> Single precision stores the deviation from the rest state, f_i - w_i (rho_0 = 1), not f_i:
!> at low Mach number the deviations that drive the flow are 1e-3..1e-6 of f_i, and a 24-bit
!> mantissa spent on the constant w_i would leave them a few bits. With 'single' every value is
!> computed in 8 bytes and only the stored population is rounded to 4; 'single_arith' stores the
!> same way and its sweep collides in 4 bytes too (dkt_mrt_sp), while everything that reads or
!> writes populations through the accessors here (boundaries, bounce-back, momentum exchange,
!> fields) still sees unshifted 8-byte values. 'half' stores the same deviations as 16-bit codes
!> (dkt_half) and collides them in 4 bytes like 'single_arith'; the accessors decode a code to
!> 4 bytes and add w_i in 8, and encode an 8-byte value by rounding f_i - w_i to 4 bytes first
!> and that to the nearest code (a deterministic double rounding: a value within 2^-24 of a
!> midpoint between two codes may land on the farther one). Copies between populations of equal
!> weight (bounce-back pairs, periodic images, halo rows, the window's row shift) move stored
!> values unchanged in every form.
module dkt_store
  use iso_fortran_env, only: int16
  use dkt_kinds, only: wp, sp
  use dkt_choices, only: PRECISION_NAMES, PRECISION_DOUBLE, PRECISION_SINGLE, &
                         PRECISION_SINGLE_UNSHIFTED, PRECISION_SINGLE_ARITH, PRECISION_HALF
  use dkt_half, only: half_encode, half_decode, half_unpack
  use dkt_errors, only: internal_error
  use dkt_text, only: itoa
  use dkt_lattice, only: w
  implicit none
  private
  public :: lattice_t, lattice_allocate, lattice_free, lattice_get, lattice_set, &
            lattice_get_row, lattice_get_node, lattice_set_node, lattice_swap, lattice_allocated, &
            lattice_bytes, lattice_precision, lattice_precision_name, PRECISION_NAMES

  type :: lattice_t
    logical :: single = .false.  !! populations stored in 4 bytes (s), otherwise in 8 (d)
    logical :: shifted = .false. !! single only: the stored value is f_i - w_i
    logical :: arith4 = .false.  !! single and shifted only: the sweep collides in 4 bytes
    !> populations stored as 16-bit codes of f_i - w_i (h; single is false), collided in 4 bytes
    logical :: half = .false.
    real(wp), pointer, contiguous :: d(:, :, :) => null() !! (0:nxp-1, 0:nyl+1, 0:8), double
    real(sp), pointer, contiguous :: s(:, :, :) => null() !! the same extents, single
    integer(int16), pointer, contiguous :: h(:, :, :) => null() !! the same extents, half
  end type lattice_t

contains

  !> Allocate f(0:nxp-1, 0:nyl+1, 0:8) in the chosen storage, every entry the rest state f_i = w_i
  !! (first touch of ghosts and padding too, so that nothing undefined is ever read).
  subroutine lattice_allocate(lat, nxp, nyl, single, shifted, arith4, half)
    type(lattice_t), intent(out) :: lat
    integer, intent(in) :: nxp, nyl
    logical, intent(in) :: single, shifted
    !> collide in 4 bytes ('single_arith'): not optional, so that no caller that sizes a lattice
    !! anew (a window that grows) can drop the mode by leaving it out
    logical, intent(in) :: arith4
    !> 16-bit codes ('half'; then single, shifted and arith4 are false), not optional either
    logical, intent(in) :: half
    integer :: i
    lat%half = half .and. .not. single
    lat%single = single
    lat%shifted = single .and. shifted
    lat%arith4 = lat%shifted .and. arith4
    if (lat%half) then
      ! the rest state is the deviation 0, code 0
      allocate (lat%h(0:nxp - 1, 0:nyl + 1, 0:8))
      lat%h = 0_int16
    else if (single) then
      allocate (lat%s(0:nxp - 1, 0:nyl + 1, 0:8))
      do i = 0, 8
        lat%s(:, :, i) = real(merge(0.0_wp, w(i), lat%shifted), sp)
      end do
    else
      allocate (lat%d(0:nxp - 1, 0:nyl + 1, 0:8))
      do i = 0, 8
        lat%d(:, :, i) = w(i)
      end do
    end if
  end subroutine lattice_allocate

  !> The storage lbm.precision asks for: single (4 bytes), shifted (f_i - w_i stored) and
  !! arith4 (collided in 4 bytes), or half (16-bit codes, the others false).
  subroutine lattice_precision(code, single, shifted, arith4, half)
    integer, intent(in) :: code !! lbm.precision as its PRECISION_* code
    logical, intent(out) :: single, shifted, arith4, half
    arith4 = .false.
    half = .false.
    select case (code)
    case (PRECISION_DOUBLE)
      single = .false.
      shifted = .false.
    case (PRECISION_SINGLE)
      single = .true.
      shifted = .true.
    case (PRECISION_SINGLE_UNSHIFTED)
      single = .true.
      shifted = .false.
    case (PRECISION_SINGLE_ARITH)
      single = .true.
      shifted = .true.
      arith4 = .true.
    case (PRECISION_HALF)
      single = .false.
      shifted = .false.
      half = .true.
    case default
      call internal_error('lattice_precision: lbm.precision code '//itoa(code))
    end select
  end subroutine lattice_precision

  !> The lbm.precision value that gives the storage of lat.
  pure function lattice_precision_name(lat) result(name)
    type(lattice_t), intent(in) :: lat
    character(len=:), allocatable :: name
    if (lat%half) then
      name = 'half'
    else if (.not. lat%single) then
      name = 'double'
    else if (lat%arith4) then
      name = 'single_arith'
    else if (lat%shifted) then
      name = 'single'
    else
      name = 'single_unshifted'
    end if
  end function lattice_precision_name

  !> Bytes of one stored population: 8 for 'double', 4 for the single forms, 2 for 'half'.
  pure integer function lattice_bytes(code) result(b)
    integer, intent(in) :: code !! lbm.precision as its PRECISION_* code
    select case (code)
    case (PRECISION_DOUBLE)
      b = storage_size(1.0_wp)/8
    case (PRECISION_SINGLE, PRECISION_SINGLE_UNSHIFTED, PRECISION_SINGLE_ARITH)
      b = storage_size(1.0_sp)/8
    case (PRECISION_HALF)
      b = storage_size(1_int16)/8
    case default
      ! pure (the memory formula is): the one stop a pure procedure may make
      error stop 'dktlbm: error: internal error: lattice_bytes: unknown lbm.precision code'
    end select
  end function lattice_bytes

  pure logical function lattice_allocated(lat)
    type(lattice_t), intent(in) :: lat
    lattice_allocated = associated(lat%d) .or. associated(lat%s) .or. associated(lat%h)
  end function lattice_allocated

  !> Exchange two lattices (f and f_next after a step): only the pointers move.
  subroutine lattice_swap(a, b)
    type(lattice_t), intent(inout) :: a, b
    type(lattice_t) :: tmp
    tmp = a
    a = b
    b = tmp
  end subroutine lattice_swap

  subroutine lattice_free(lat)
    type(lattice_t), intent(inout) :: lat
    if (associated(lat%d)) deallocate (lat%d)
    if (associated(lat%s)) deallocate (lat%s)
    if (associated(lat%h)) deallocate (lat%h)
    nullify (lat%d, lat%s, lat%h)
  end subroutine lattice_free

  !> Population i at node (x, j), in 8 bytes and unshifted.
  pure real(wp) function lattice_get(lat, x, j, i) result(v)
    type(lattice_t), intent(in) :: lat
    integer, intent(in) :: x, j, i
    if (lat%half) then
      v = real(half_decode(lat%h(x, j, i)), wp) + w(i)
    else if (lat%single) then
      v = real(lat%s(x, j, i), wp)
      if (lat%shifted) v = v + w(i)
    else
      v = lat%d(x, j, i)
    end if
  end function lattice_get

  !> Store population i at node (x, j) (rounded to 4 bytes in single precision, to 4 bytes and
  !! then to a 16-bit code in half).
  subroutine lattice_set(lat, x, j, i, v)
    type(lattice_t), intent(inout) :: lat
    integer, intent(in) :: x, j, i
    real(wp), intent(in) :: v
    if (lat%half) then
      lat%h(x, j, i) = half_encode(real(v - w(i), sp))
    else if (lat%single) then
      if (lat%shifted) then
        lat%s(x, j, i) = real(v - w(i), sp)
      else
        lat%s(x, j, i) = real(v, sp)
      end if
    else
      lat%d(x, j, i) = v
    end if
  end subroutine lattice_set

  !> The nine populations at node (x, j), in 8 bytes and unshifted.
  pure function lattice_get_node(lat, x, j) result(fn)
    type(lattice_t), intent(in) :: lat
    integer, intent(in) :: x, j
    real(wp) :: fn(0:8)
    if (lat%half) then
      fn = real(half_decode(lat%h(x, j, :)), wp) + w
    else if (lat%single) then
      fn = real(lat%s(x, j, :), wp)
      if (lat%shifted) fn = fn + w
    else
      fn = lat%d(x, j, :)
    end if
  end function lattice_get_node

  !> The nine populations of columns 1..nx of row j, in 8 bytes and unshifted, as
  !! lattice_get_node gives them node by node (fr(x, i) is population i of column x): the row
  !! form, whose loops vectorise along x.
  pure subroutine lattice_get_row(lat, j, nx, fr)
    type(lattice_t), intent(in) :: lat
    integer, intent(in) :: j, nx
    real(wp), intent(out), contiguous :: fr(:, 0:)
    real(sp), allocatable :: decoded(:)
    integer :: i
    do i = 0, 8
      if (lat%half) then
        if (.not. allocated(decoded)) allocate (decoded(0:size(lat%h, 1) - 1))
        call half_unpack(lat%h, size(lat%h, 1), size(lat%h, 2) - 2, j, i, 1, nx, decoded)
        call widen_row(decoded(1:nx), .true., w(i), fr(1:nx, i), nx)
      else if (.not. lat%single) then
        call copy_row(lat%d(1:nx, j, i), fr(1:nx, i), nx)
      else
        call widen_row(lat%s(1:nx, j, i), lat%shifted, w(i), fr(1:nx, i), nx)
      end if
    end do
  end subroutine lattice_get_row

  !> A 4-byte row in 8 bytes, plus w_i where the lattice stores f_i - w_i. The rows here and in
  !! copy_row are explicit-shape: through the pointer components the loops read one value at a
  !! time with a stride, and the guards, which read every row each run.guard_every steps, took
  !! longer than the flow.
  pure subroutine widen_row(d, shifted, wi, fr, n)
    integer, intent(in) :: n
    real(sp), intent(in) :: d(n)
    logical, intent(in) :: shifted
    real(wp), intent(in) :: wi
    real(wp), intent(out) :: fr(n)
    if (shifted) then
      fr = real(d, wp) + wi
    else
      fr = real(d, wp)
    end if
  end subroutine widen_row

  !> An 8-byte row, as it is stored (see widen_row).
  pure subroutine copy_row(d, fr, n)
    integer, intent(in) :: n
    real(wp), intent(in) :: d(n)
    real(wp), intent(out) :: fr(n)
    fr = d
  end subroutine copy_row

  !> Store the nine populations at node (x, j).
  subroutine lattice_set_node(lat, x, j, fn)
    type(lattice_t), intent(inout) :: lat
    integer, intent(in) :: x, j
    real(wp), intent(in) :: fn(0:8)
    if (lat%half) then
      lat%h(x, j, :) = half_encode(real(fn - w, sp))
    else if (lat%single) then
      if (lat%shifted) then
        lat%s(x, j, :) = real(fn - w, sp)
      else
        lat%s(x, j, :) = real(fn, sp)
      end if
    else
      lat%d(x, j, :) = fn
    end if
  end subroutine lattice_set_node

end module dkt_store

!> The fused pull-stream + collide sweep for lbm.precision = 'half': populations stored as 16-bit
!> codes of f_i - w_i (dkt_half), collided in 4 bytes exactly as 'single_arith' collides them
!> (dkt_mrt_sp), in place or between two lattices, with the same row order and the same parts
!> around the halo exchange as dkt_mrt's sweep (docs/design.md, "In-place streaming").
!>
!> Row j is done in three passes over 4-byte row buffers that stay in cache: decode what the
!> row pulls (0, 1, 3 from its own row, 4, 7, 8 from row j+1; 2, 5, 6 of row j-1 were decoded
!> as the previous row passed, into `below`), collide every node into a 4-byte row, encode that
!> row into row j. Every stored code is decoded once and encoded once a step. The passes keep
!> the format's functions in their own module and still vectorise: the decoding and encoding
!> loops inline the format there, the collision loop inlines the collision in dkt_mrt_sp. In
!> place, row j's old populations 2, 5, 6 are decoded (into `saved`) before row j is
!> overwritten, and row j+1 is read before it is swept, so every node sees the values the
!> two-lattice sweep gives it and the results have the same bits (tests/test_half.f90).
module dkt_mrt_half
  use iso_fortran_env, only: int16
  use dkt_kinds, only: sp
  use dkt_store, only: lattice_t
  use dkt_half, only: half_unpack, half_unpack_row, half_pack_row
  use dkt_mrt_sp, only: collision_sp_t, rows_from_rows_sp
  implicit none
  private
  public :: half_sweep_t, half_sweep_init, half_sweep_rows

  !> Row buffers of the 16-bit sweep (0:nxp-1 columns each), allocated once per run.
  type :: half_sweep_t
    real(sp), allocatable :: pulled(:, :)  !! (0:nxp-1, 0:8): deviations 0, 1, 3 of row j, 4, 7, 8
    !!                                        of row j+1, decoded (2, 5, 6 unused)
    real(sp), allocatable :: post(:, :)    !! (0:nxp-1, 0:8): the post-collision row, 4 bytes
    real(sp), allocatable :: below(:, :)   !! (0:nxp-1, 3): old row j-1, deviations 2, 5, 6
    real(sp), allocatable :: saved(:, :)   !! the same of old row j, for row j+1
    real(sp), allocatable :: kept_dn(:, :) !! `below` left by a part, for the part above it
    integer(int16), allocatable :: kept_up(:, :) !! (0:nxp-1, 0:8): an old first row of a part
    integer(int16), allocatable :: swap(:, :)    !! room for a row while kept_up stands in for it
  end type half_sweep_t

  integer, parameter :: up3(3) = [2, 5, 6] !! the populations with c_y = +1

contains

  subroutine half_sweep_init(ws, nxp)
    type(half_sweep_t), intent(out) :: ws
    integer, intent(in) :: nxp
    allocate (ws%pulled(0:nxp - 1, 0:8), ws%post(0:nxp - 1, 0:8), ws%below(0:nxp - 1, 3), &
              ws%saved(0:nxp - 1, 3), ws%kept_dn(0:nxp - 1, 3), ws%kept_up(0:nxp - 1, 0:8), &
              ws%swap(0:nxp - 1, 0:8))
    ws%pulled = 0.0_sp
    ws%post = 0.0_sp
    ws%below = 0.0_sp
    ws%saved = 0.0_sp
    ws%kept_dn = 0.0_sp
    ws%kept_up = 0_int16
    ws%swap = 0_int16
  end subroutine half_sweep_init

  !> Stream and collide rows j1..j2 from src into dst, in place when dst is src; keep,
  !! below_kept and above_kept (in place only) as in dkt_mrt's sweep_rows.
  subroutine half_sweep_rows(c, ws, src, dst, nx, nyl, j1, j2, keep, below_kept, above_kept)
    type(collision_sp_t), intent(in) :: c
    type(half_sweep_t), intent(inout) :: ws
    type(lattice_t), intent(in) :: src
    type(lattice_t), intent(inout) :: dst
    integer, intent(in) :: nx, nyl, j1, j2
    logical, intent(in) :: keep, below_kept, above_kept
    real(sp), allocatable :: spare(:, :)
    logical :: in_place
    integer :: j, k, nxp
    if (j2 < j1) return
    nxp = size(dst%h, 1)
    in_place = associated(src%h, dst%h)
    if (in_place .and. keep) ws%kept_up = dst%h(:, j1, :)
    if (in_place .and. below_kept) then
      ws%below = ws%kept_dn
    else
      do k = 1, 3
        call half_unpack(src%h, nxp, nyl, j1 - 1, up3(k), 0, nx + 1, ws%below(:, k))
      end do
    end if
    ! the row above the last comes from kept_up: put it in row j2+1 for the last row's sweep
    if (in_place .and. above_kept) then
      ws%swap = dst%h(:, j2 + 1, :)
      dst%h(:, j2 + 1, :) = ws%kept_up
    end if
    do j = j1, j2
      call half_unpack_row(src%h, nxp, nyl, j, 0, nx + 1, ws%pulled, ws%saved)
      call rows_from_rows_sp(c, ws%pulled, ws%below, ws%post, nxp, nx)
      call half_pack_row(ws%post, dst%h, nxp, nyl, j, 1, nx)
      ! old row j's populations 2, 5, 6 are the next row's below: swap the buffers, not copy
      call move_alloc(ws%below, spare)
      call move_alloc(ws%saved, ws%below)
      call move_alloc(spare, ws%saved)
    end do
    if (in_place .and. above_kept) dst%h(:, j2 + 1, :) = ws%swap
    if (in_place .and. keep) ws%kept_dn = ws%below
  end subroutine half_sweep_rows

end module dkt_mrt_half

!> Run diagnostics and guards: a non-finite population or a Mach number above the limit stops
!> the run with what, where, when, and what to change.
module dkt_diagnostics
  use ieee_arithmetic, only: ieee_is_finite
  use mpi_f08, only: MPI_Allreduce, MPI_IN_PLACE, MPI_MAX
  use dkt_kinds, only: wp, mpi_wp, cs2
  use dkt_domain, only: domain_t
  use dkt_fields, only: node_moments
  use dkt_errors, only: fatal_local
  implicit none
  private
  public :: guard_check

contains

  !> Check every node of the slab; stop all ranks on a non-finite value or |u|/c_s above
  !! mach_limit. Returns the largest Mach number over all ranks (a collective call).
  subroutine guard_check(dom, f, force, mach_limit, step, t, dx, mach_max)
    type(domain_t), intent(in) :: dom
    real(wp), intent(in) :: f(0:, 0:, 0:)
    real(wp), intent(in) :: force(2)      !! body force, lattice units
    real(wp), intent(in) :: mach_limit    !! largest allowed |u|/c_s
    integer, intent(in) :: step           !! time step
    real(wp), intent(in) :: t, dx         !! time (s) and lattice spacing (cm), for the message
    real(wp), intent(out) :: mach_max     !! largest |u|/c_s on any rank
    real(wp) :: rho, ux, uy, ma
    integer :: x, j
    character(len=512) :: msg

    mach_max = 0.0_wp
    do j = 1, dom%nyl
      do x = 1, dom%nx
        call node_moments(f(x, j, :), force, rho, ux, uy)
        if (.not. (all(ieee_is_finite(f(x, j, :))) .and. ieee_is_finite(ux) .and. &
                   ieee_is_finite(uy))) then
          write (msg, '(a,i0,a,es12.4e3,a,2(i0,a),2(es12.4e3,a),a)') 'non-finite value at step ', &
            step, ' (t = ', t, ' s), node (', x, ', ', dom%y0 + j, ') at (', (x - 0.5_wp)*dx, &
            ', ', (dom%y0 + j - 0.5_wp)*dx, ') cm. The run became unstable: increase lbm.tau,', &
            ' refine lbm.dx (smaller dt), or lower the velocity scale'
          call fatal_local(trim(msg))
        end if
        ma = sqrt((ux*ux + uy*uy)/cs2)
        if (ma > mach_limit) then
          write (msg, '(a,es12.4e3,a,es12.4e3,a,i0,a,es12.4e3,a,2(i0,a),2(es12.4e3,a),a)') &
            'Mach number ', ma, ' above run.mach_limit = ', mach_limit, ' at step ', step, &
            ' (t = ', t, ' s), node (', x, ', ', dom%y0 + j, ') at (', (x - 0.5_wp)*dx, ', ', &
            (dom%y0 + j - 0.5_wp)*dx, ') cm. Refine lbm.dx or lower lbm.tau (both shrink dt', &
            ' and the lattice velocity), or lower the flow speed'
          call fatal_local(trim(msg))
        end if
        mach_max = max(mach_max, ma)
      end do
    end do
    call MPI_Allreduce(MPI_IN_PLACE, mach_max, 1, mpi_wp, MPI_MAX, dom%comm)
  end subroutine guard_check

end module dkt_diagnostics

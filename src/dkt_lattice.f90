!> The D2Q9 lattice (docs/model.md §1): velocities, weights, opposite directions, the Lallemand–Luo
!> moment matrix (E1) and the second-order equilibrium whose moments are E2.
module dkt_lattice
  use dkt_kinds, only: wp, cs2
  implicit none
  private
  public :: q, ex, ey, w, opp, moment_matrix, moment_norm, equilibrium, moment_names
  public :: e3_heat_flux_rate

  integer, parameter :: q = 9 !! number of discrete velocities
  !> lattice velocities e_i = (ex(i), ey(i)), i = 0..8, in the order of docs/model.md §1
  integer, parameter :: ex(0:8) = [0, 1, 0, -1, 0, 1, -1, -1, 1]
  integer, parameter :: ey(0:8) = [0, 0, 1, 0, -1, 1, 1, -1, -1]
  !> weights w_i
  real(wp), parameter :: w(0:8) = [4.0_wp/9.0_wp, &
                                   1.0_wp/9.0_wp, 1.0_wp/9.0_wp, 1.0_wp/9.0_wp, 1.0_wp/9.0_wp, &
                                   1.0_wp/36.0_wp, 1.0_wp/36.0_wp, 1.0_wp/36.0_wp, 1.0_wp/36.0_wp]
  !> index of the opposite velocity, e_opp(i) = -e_i
  integer, parameter :: opp(0:8) = [0, 3, 4, 1, 2, 7, 8, 5, 6]

  !> E1: rows are the moments (rho, e, eps, jx, qx, jy, qy, pxx, pxy), columns the populations.
  !! Stored so that moment_matrix(m, i) is row m, column i.
  integer, parameter :: rows(81) = [1, 1, 1, 1, 1, 1, 1, 1, 1, &
                                    -4, -1, -1, -1, -1, 2, 2, 2, 2, &
                                    4, -2, -2, -2, -2, 1, 1, 1, 1, &
                                    0, 1, 0, -1, 0, 1, -1, -1, 1, &
                                    0, -2, 0, 2, 0, 1, -1, -1, 1, &
                                    0, 0, 1, 0, -1, 1, 1, -1, -1, &
                                    0, 0, -2, 0, 2, 1, 1, -1, -1, &
                                    0, 1, -1, 1, -1, 0, 0, 0, 0, &
                                    0, 0, 0, 0, 0, 1, -1, 1, -1]
  real(wp), parameter :: moment_matrix(0:8, 0:8) = real(reshape(rows, [9, 9], order=[2, 1]), wp)
  !> squared norms of the (orthogonal) rows: M^-1 = M^T diag(1/moment_norm)
  real(wp), parameter :: moment_norm(0:8) = [9, 36, 36, 6, 12, 6, 12, 4, 4]*1.0_wp
  character(len=3), parameter :: moment_names(0:8) = &
                                 ['rho', 'e  ', 'eps', 'jx ', 'qx ', 'jy ', 'qy ', 'pxx', 'pxy']

contains

  !> E3: the heat-flux rate s_q = 8(2 - s_nu)/(8 - s_nu) that places a bounce-back wall exactly
  !! half-way between nodes, whatever the viscosity.
  pure real(wp) function e3_heat_flux_rate(s_nu) result(s_q)
    real(wp), intent(in) :: s_nu !! viscous rate 1/tau
    s_q = 8.0_wp*(2.0_wp - s_nu)/(8.0_wp - s_nu)
  end function e3_heat_flux_rate

  !> Second-order equilibrium f_i^eq(rho, u); its moments under E1 are exactly E2.
  pure function equilibrium(rho, ux, uy) result(feq)
    real(wp), intent(in) :: rho    !! density (lattice units)
    real(wp), intent(in) :: ux, uy !! velocity (lattice units)
    real(wp) :: feq(0:8)
    real(wp) :: eu, usq
    integer :: i
    usq = ux*ux + uy*uy
    do i = 0, 8
      eu = ex(i)*ux + ey(i)*uy
      feq(i) = w(i)*rho*(1.0_wp + eu/cs2 + 0.5_wp*eu*eu/(cs2*cs2) - 0.5_wp*usq/cs2)
    end do
  end function equilibrium

end module dkt_lattice

!> Macroscopic fields from the populations: density, velocity (with the half-force shift of
!> Guo's scheme), vorticity and pressure, on one slab. Used for output and the guards.
module dkt_fields
  use mpi_f08, only: MPI_Sendrecv, MPI_STATUS_IGNORE, MPI_PROC_NULL
  use dkt_kinds, only: wp, mpi_wp
  use dkt_domain, only: domain_t
  use dkt_store, only: lattice_t, lattice_get_node
  implicit none
  private
  public :: node_moments, row_speed2, macroscopic, vorticity

contains

  !> Density and velocity at one node from its post-collision populations f*; the collision
  !! added the full force to the momentum, so u = (sum e f* - F/2)/rho is the velocity it used.
  pure subroutine node_moments(fn, force, rho, ux, uy)
    real(wp), intent(in) :: fn(0:8)     !! post-collision populations of the node
    real(wp), intent(in) :: force(2)    !! body force, lattice units
    real(wp), intent(out) :: rho, ux, uy
    rho = sum(fn)
    ux = (fn(1) - fn(3) + fn(5) - fn(6) - fn(7) + fn(8) - 0.5_wp*force(1))/rho
    uy = (fn(2) - fn(4) + fn(5) + fn(6) - fn(7) - fn(8) - 0.5_wp*force(2))/rho
  end subroutine node_moments

  !> The density and the squared speed u_x² + u_y² of each column of one row (fr as
  !! lattice_get_row gives it), each node's moments in node_moments' order of operations, so
  !! that each value has its bits; the loop vectorises along x.
  pure subroutine row_speed2(fr, nx, force, rho, u2)
    real(wp), intent(in) :: fr(:, 0:)
    integer, intent(in) :: nx
    real(wp), intent(in) :: force(2)
    real(wp), intent(out) :: rho(:), u2(:)
    real(wp) :: ux, uy
    integer :: x
    do x = 1, nx
      rho(x) = fr(x, 0) + fr(x, 1) + fr(x, 2) + fr(x, 3) + fr(x, 4) + fr(x, 5) + fr(x, 6) + &
               fr(x, 7) + fr(x, 8)
      ux = (fr(x, 1) - fr(x, 3) + fr(x, 5) - fr(x, 6) - fr(x, 7) + fr(x, 8) - &
            0.5_wp*force(1))/rho(x)
      uy = (fr(x, 2) - fr(x, 4) + fr(x, 5) + fr(x, 6) - fr(x, 7) - fr(x, 8) - &
            0.5_wp*force(2))/rho(x)
      u2(x) = ux*ux + uy*uy
    end do
  end subroutine row_speed2

  !> rho, ux, uy (lattice units) on rows 1..nyl of the slab, from the unshifted 8-byte
  !! populations whatever lbm.precision stores.
  subroutine macroscopic(dom, f, force, rho, ux, uy)
    type(domain_t), intent(in) :: dom
    type(lattice_t), intent(in) :: f
    real(wp), intent(in) :: force(2)
    real(wp), intent(out) :: rho(:, :), ux(:, :), uy(:, :)
    integer :: x, j
    do j = 1, dom%nyl
      do x = 1, dom%nx
        call node_moments(lattice_get_node(f, x, j), force, rho(x, j), ux(x, j), uy(x, j))
      end do
    end do
  end subroutine macroscopic

  !> Vorticity dv/dx - du/dy (per time step, lattice units) by central differences; one-sided
  !! next to a wall or an open end. Exchanges one row of velocity with the neighbours, so the
  !! value at a node does not depend on how the rows are split.
  subroutine vorticity(dom, ux, uy, periodic_x, vort)
    type(domain_t), intent(in) :: dom
    real(wp), intent(in) :: ux(:, :), uy(:, :)
    logical, intent(in) :: periodic_x
    real(wp), intent(out) :: vort(:, :)
    real(wp), allocatable :: u(:, :)
    integer :: nx, nyl, x, j, xm, xp
    real(wp) :: dvdx, dudy, hx

    nx = dom%nx
    nyl = dom%nyl
    allocate (u(nx, 0:nyl + 1))
    u(:, 1:nyl) = ux
    call MPI_Sendrecv(u(:, nyl), nx, mpi_wp, dom%above, 21, u(:, 0), nx, mpi_wp, dom%below, 21, &
                      dom%comm, MPI_STATUS_IGNORE)
    call MPI_Sendrecv(u(:, 1), nx, mpi_wp, dom%below, 22, u(:, nyl + 1), nx, mpi_wp, dom%above, &
                      22, dom%comm, MPI_STATUS_IGNORE)
    do j = 1, nyl
      do x = 1, nx
        if (j == 1 .and. dom%below == MPI_PROC_NULL) then
          dudy = u(x, 2) - u(x, 1)
        else if (j == nyl .and. dom%above == MPI_PROC_NULL) then
          dudy = u(x, nyl) - u(x, nyl - 1)
        else
          dudy = 0.5_wp*(u(x, j + 1) - u(x, j - 1))
        end if
        xm = x - 1
        xp = x + 1
        hx = 0.5_wp
        if (periodic_x) then
          xm = modulo(xm - 1, nx) + 1
          xp = modulo(xp - 1, nx) + 1
        else if (x == 1) then
          xm = 1
          hx = 1.0_wp
        else if (x == nx) then
          xp = nx
          hx = 1.0_wp
        end if
        dvdx = hx*(uy(xp, j) - uy(xm, j))
        vort(x, j) = dvdx - dudy
      end do
    end do
  end subroutine vorticity

end module dkt_fields

!> The state of resolved disks as a structure of arrays (docs/design.md, "Data layout"): one
!> array per component, so that the loops over the particles a slab holds (links, refills,
!> contacts, motion) read each component contiguously. A record of one disk (`particle_t`)
!> remains for the whole scene that every rank builds or gathers (set-up, output, checkpoints),
!> and each state travels in a message as NPACK numbers (state_pack, state_unpack). The arrays
!> grow by doubling (fit_int, fit_real), as the message buffers do.
module dkt_particle_state
  use dkt_kinds, only: wp
  use dkt_choices, only: MOTION_FREE
  implicit none
  private
  public :: particle_t, particle_state_t, NPACK, fit_int, fit_real, state_fit, state_put, &
            state_copy, state_copy_first, state_pack, state_unpack, record_unpack

  !> One rigid disk, lattice units: an entry of the whole scene.
  type :: particle_t
    integer :: id = 0                 !! its number in the scene, 1..count
    real(wp) :: x = 0, y = 0          !! centre
    real(wp) :: r = 0                 !! radius
    real(wp) :: u = 0, v = 0          !! velocity
    real(wp) :: omega = 0             !! angular velocity (counter-clockwise)
    real(wp) :: density_ratio = 1     !! rho_p / rho_f
    real(wp) :: mass = 0, inertia = 0 !! M = rho_p pi r^2, I = M r^2 / 2 (per unit depth)
    integer :: motion = MOTION_FREE
    real(wp) :: fx = 0, fy = 0, torque = 0    !! hydrodynamic force and torque of the last step
    real(wp) :: cx = 0, cy = 0                !! collision force of the last step
  end type particle_t

  !> The disks a slab holds, one array per component of particle_t (element k of each is disk
  !! k); the arrays grow together (state_fit) and are at least as long as the disks held.
  type :: particle_state_t
    integer, allocatable :: id(:)
    real(wp), allocatable :: x(:), y(:), r(:), u(:), v(:), omega(:), density_ratio(:)
    real(wp), allocatable :: mass(:), inertia(:)
    integer, allocatable :: motion(:)
    real(wp), allocatable :: fx(:), fy(:), torque(:), cx(:), cy(:)
  end type particle_state_t

  !> The values a message carries per particle (state_pack)
  integer, parameter :: NPACK = 16

contains

  !> Make every array of s at least n long, keeping its values.
  subroutine state_fit(s, n)
    type(particle_state_t), intent(inout) :: s
    integer, intent(in) :: n
    call fit_int(s%id, n)
    call fit_int(s%motion, n)
    call fit_real(s%x, n); call fit_real(s%y, n); call fit_real(s%r, n)
    call fit_real(s%u, n); call fit_real(s%v, n); call fit_real(s%omega, n)
    call fit_real(s%density_ratio, n); call fit_real(s%mass, n); call fit_real(s%inertia, n)
    call fit_real(s%fx, n); call fit_real(s%fy, n); call fit_real(s%torque, n)
    call fit_real(s%cx, n); call fit_real(s%cy, n)
  end subroutine state_fit

  !> Make a at least n long, keeping its values (twice as long when it grows: no allocation
  !! in most steps)
  subroutine fit_int(a, n)
    integer, allocatable, intent(inout) :: a(:)
    integer, intent(in) :: n
    integer, allocatable :: grown(:)
    if (.not. allocated(a)) allocate (a(0))
    if (size(a) >= n) return
    allocate (grown(max(n, 2*size(a), 16)))
    grown(1:size(a)) = a
    call move_alloc(grown, a)
  end subroutine fit_int

  !> fit_int for numbers
  subroutine fit_real(a, n)
    real(wp), allocatable, intent(inout) :: a(:)
    integer, intent(in) :: n
    real(wp), allocatable :: grown(:)
    if (.not. allocated(a)) allocate (a(0))
    if (size(a) >= n) return
    allocate (grown(max(n, 2*size(a), 16)))
    grown(1:size(a)) = a
    call move_alloc(grown, a)
  end subroutine fit_real

  !> Disk k of s becomes the record p (s is long enough).
  pure subroutine state_put(s, k, p)
    type(particle_state_t), intent(inout) :: s
    integer, intent(in) :: k
    type(particle_t), intent(in) :: p
    s%id(k) = p%id; s%x(k) = p%x; s%y(k) = p%y; s%r(k) = p%r; s%u(k) = p%u; s%v(k) = p%v
    s%omega(k) = p%omega; s%density_ratio(k) = p%density_ratio; s%mass(k) = p%mass
    s%inertia(k) = p%inertia; s%motion(k) = p%motion; s%fx(k) = p%fx; s%fy(k) = p%fy
    s%torque(k) = p%torque; s%cx(k) = p%cx; s%cy(k) = p%cy
  end subroutine state_put

  !> Disk kd of dst becomes disk ks of src (dst is long enough).
  pure subroutine state_copy(dst, kd, src, ks)
    type(particle_state_t), intent(inout) :: dst
    integer, intent(in) :: kd, ks
    type(particle_state_t), intent(in) :: src
    dst%id(kd) = src%id(ks); dst%x(kd) = src%x(ks); dst%y(kd) = src%y(ks)
    dst%r(kd) = src%r(ks); dst%u(kd) = src%u(ks); dst%v(kd) = src%v(ks)
    dst%omega(kd) = src%omega(ks); dst%density_ratio(kd) = src%density_ratio(ks)
    dst%mass(kd) = src%mass(ks); dst%inertia(kd) = src%inertia(ks)
    dst%motion(kd) = src%motion(ks); dst%fx(kd) = src%fx(ks); dst%fy(kd) = src%fy(ks)
    dst%torque(kd) = src%torque(ks); dst%cx(kd) = src%cx(ks); dst%cy(kd) = src%cy(ks)
  end subroutine state_copy

  !> The first n disks of dst become those of src (dst grows as needed).
  subroutine state_copy_first(dst, src, n)
    type(particle_state_t), intent(inout) :: dst
    type(particle_state_t), intent(in) :: src
    integer, intent(in) :: n
    call state_fit(dst, n)
    dst%id(1:n) = src%id(1:n); dst%x(1:n) = src%x(1:n); dst%y(1:n) = src%y(1:n)
    dst%r(1:n) = src%r(1:n); dst%u(1:n) = src%u(1:n); dst%v(1:n) = src%v(1:n)
    dst%omega(1:n) = src%omega(1:n); dst%density_ratio(1:n) = src%density_ratio(1:n)
    dst%mass(1:n) = src%mass(1:n); dst%inertia(1:n) = src%inertia(1:n)
    dst%motion(1:n) = src%motion(1:n); dst%fx(1:n) = src%fx(1:n); dst%fy(1:n) = src%fy(1:n)
    dst%torque(1:n) = src%torque(1:n); dst%cx(1:n) = src%cx(1:n); dst%cy(1:n) = src%cy(1:n)
  end subroutine state_copy_first

  !> Disk k of s as the NPACK numbers of a message.
  pure subroutine state_pack(s, k, v)
    type(particle_state_t), intent(in) :: s
    integer, intent(in) :: k
    real(wp), intent(out) :: v(NPACK)
    v = [real(s%id(k), wp), s%x(k), s%y(k), s%r(k), s%u(k), s%v(k), s%omega(k), &
         s%density_ratio(k), s%mass(k), s%inertia(k), real(s%motion(k), wp), s%fx(k), &
         s%fy(k), s%torque(k), s%cx(k), s%cy(k)]
  end subroutine state_pack

  !> Disk k of s from the NPACK numbers of a message (s is long enough): through the record,
  !! so that record_unpack alone reads the message's order.
  pure subroutine state_unpack(v, s, k)
    real(wp), intent(in) :: v(NPACK)
    type(particle_state_t), intent(inout) :: s
    integer, intent(in) :: k
    type(particle_t) :: p
    call record_unpack(v, p)
    call state_put(s, k, p)
  end subroutine state_unpack

  !> A record from the NPACK numbers of a message.
  pure subroutine record_unpack(v, p)
    real(wp), intent(in) :: v(NPACK)
    type(particle_t), intent(out) :: p
    p%id = nint(v(1)); p%x = v(2); p%y = v(3); p%r = v(4); p%u = v(5); p%v = v(6)
    p%omega = v(7); p%density_ratio = v(8); p%mass = v(9); p%inertia = v(10)
    p%motion = nint(v(11)); p%fx = v(12); p%fy = v(13); p%torque = v(14); p%cx = v(15)
    p%cy = v(16)
  end subroutine record_unpack
end module dkt_particle_state

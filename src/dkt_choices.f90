!> The choices of the input (lbm.collision, coupling.bounce_back, domain.lower, ...) as named
!> integer constants. The input layer turns each choice's text into its constant once, at load
!> (dkt_config_types, config_choices); every other module compares the integers, and a
!> `select case` on one stops with an internal error on a value it does not know. The texts stay
!> the contract (namelist keys, messages, the run file).
!>
!> Each `*_NAMES` list holds the texts in the order of their constants: word k of the list is
!> constant k, so the list is also what the input allows for its key.
module dkt_choices
  implicit none
  private
  public :: choice_code

  !> domain.sides, domain.lower, domain.upper: what closes the channel (dkt_boundary)
  character(len=*), parameter, public :: END_NAMES = 'wall periodic velocity outflow'
  integer, parameter, public :: END_WALL = 1, END_PERIODIC = 2, END_VELOCITY = 3, END_OUTFLOW = 4

  !> lbm.collision: multiple-relaxation-time (E1) or BGK (E4)
  character(len=*), parameter, public :: COLLISION_NAMES = 'mrt bgk'
  integer, parameter, public :: COLLISION_MRT = 1, COLLISION_BGK = 2

  !> lbm.streaming: one lattice swept in place, or two
  character(len=*), parameter, public :: STREAMING_NAMES = 'in_place two_lattice'
  integer, parameter, public :: STREAMING_IN_PLACE = 1, STREAMING_TWO_LATTICE = 2

  !> lbm.precision: 8 bytes; 4 bytes holding f_i - w_i; 4 bytes holding f_i (the naive form,
  !! only there to measure what the shift buys); 4 bytes holding f_i - w_i and collided in 4
  !! bytes too (dkt_store, dkt_mrt_sp); f_i - w_i in 16-bit codes, collided in 4 bytes (dkt_half)
  character(len=*), parameter, public :: PRECISION_NAMES = &
                                         'double single single_unshifted single_arith half'
  integer, parameter, public :: PRECISION_DOUBLE = 1, PRECISION_SINGLE = 2, &
                                PRECISION_SINGLE_UNSHIFTED = 3, PRECISION_SINGLE_ARITH = 4, &
                                PRECISION_HALF = 5

  !> inlet.profile: the shape of the inlet velocity across the channel
  character(len=*), parameter, public :: PROFILE_NAMES = 'uniform parabolic'
  integer, parameter, public :: PROFILE_UNIFORM = 1, PROFILE_PARABOLIC = 2

  !> initial.flow: the flow at t = 0
  character(len=*), parameter, public :: FLOW_NAMES = 'rest taylor_green'
  integer, parameter, public :: FLOW_REST = 1, FLOW_TAYLOR_GREEN = 2

  !> initial.pressure: the fluid's pressure at t = 0, uniform or holding up the free particles
  character(len=*), parameter, public :: PRESSURE_NAMES = 'uniform hydrostatic'
  integer, parameter, public :: PRESSURE_UNIFORM = 1, PRESSURE_HYDROSTATIC = 2

  !> particles.motion: moved by fluid and gravity (E8), at rest, or at its given velocity
  character(len=*), parameter, public :: MOTION_NAMES = 'free fixed prescribed'
  integer, parameter, public :: MOTION_FREE = 1, MOTION_FIXED = 2, MOTION_PRESCRIBED = 3

  !> coupling.bounce_back: the bounce-back on a particle's surface (E6)
  character(len=*), parameter, public :: BB_NAMES = 'halfway yu bfl'
  integer, parameter, public :: BB_HALFWAY = 1, BB_YU = 2, BB_BFL = 3

  !> coupling.momentum: the momentum exchange (E7), the paper's or Galilean-invariant
  character(len=*), parameter, public :: MOMENTUM_NAMES = 'paper galilean'
  integer, parameter, public :: MOMENTUM_PAPER = 1, MOMENTUM_GALILEAN = 2

  !> coupling.interior: the nodes inside a particle, solid (reset) or fluid
  character(len=*), parameter, public :: INTERIOR_NAMES = 'solid fluid'
  integer, parameter, public :: INTERIOR_SOLID = 1, INTERIOR_FLUID = 2

contains

  !> The constant of the text `value` in the list `names` (its word number), 0 if it is not
  !! one of them.
  pure integer function choice_code(value, names) result(code)
    character(len=*), intent(in) :: value !! the choice as read, trailing blanks ignored
    character(len=*), intent(in) :: names !! one of the *_NAMES lists
    integer :: a, b
    code = 0
    a = 1
    do while (a <= len(names))
      b = index(names(a:)//' ', ' ') + a - 1
      code = code + 1
      if (names(a:b - 1) == trim(value)) return
      a = b + 1
    end do
    code = 0
  end function choice_code

end module dkt_choices

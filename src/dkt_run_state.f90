!> The state of one run, shared by the time loop and its services (output, reports,
!> checkpoints): the configuration and lattice parameters, the slab, the two lattices, the
!> particles, the window, the pair's diagnostics, the open output and what ended the run.
!> A separate module so that each service can act on the run without the loop's module.
module dkt_run_state
  use dkt_config, only: config_t, lattice_params_t
  use dkt_mrt, only: collision_t, sweep_t
  use dkt_domain, only: domain_t
  use dkt_boundary, only: boundary_t
  use dkt_particles, only: particles_t
  use dkt_window, only: window_t
  use dkt_diagnostics, only: pair_diag_t
  use dkt_io, only: io_t
  use dkt_store, only: lattice_t
  implicit none
  private
  public :: simulation_t, path_t

  !> a file name, as an element of a list of names of different lengths

  type :: path_t
    character(len=:), allocatable :: s
  end type path_t

  type :: simulation_t
    type(config_t) :: cfg
    type(lattice_params_t) :: lp
    type(domain_t) :: dom
    type(boundary_t) :: bc
    type(collision_t) :: coll
    type(lattice_t) :: f      !! post-collision f*(t), stored as lbm.precision says
    type(lattice_t) :: f_next !! f*(t + dt), written by the sweep
    logical :: in_place = .false.   !! lbm.streaming = 'in_place': f_next is f itself
    type(sweep_t) :: ws             !! the row buffers of the in-place sweep
    type(particles_t) :: parts      !! allocated only when the scene has particles
    logical :: particles_on = .false.
    logical :: particles_move = .false. !! some particle is free or prescribed
    type(window_t) :: win           !! used only when the scene asks for a window
    logical :: window_on = .false.
    type(pair_diag_t) :: pair       !! particles 1 and 2, when the scene has two or more
    logical :: pair_on = .false.
    type(io_t) :: io
    logical :: output_open = .false.
    integer :: csv_unit = 0         !! the diagnostics CSV file (rank 0, when the pair is on)
    logical :: csv_open = .false.
    integer :: step = 0
    integer :: samples = 0          !! samples of the /particles series written
    character(len=:), allocatable :: stopped_early !! why the run ended before its last step
    !> why the run ended, stored as /run stop_reason when the output is closed: 'finished',
    !! 'window_escape', 'signal', 'wall_limit', 'guard: <message>' or 'error: <message>'
    character(len=:), allocatable :: stop_reason
    integer :: fields_step = -1     !! the step of the last field snapshot written
    integer :: series_step = -1     !! the step of the last /particles sample written
    logical :: reported = .false.   !! the pair's pattern and episodes are written
    logical :: restarted = .false.  !! the run resumed from a checkpoint
    logical :: interrupted = .false. !! stopped on a signal or the wall limit, to be resumed
    character(len=:), allocatable :: restart_from !! the checkpoint it resumed from
    !> the changes of the input run.restart_changes allowed on resuming, for the run file:
    !! 'group.key old -> new; ...', '' if none
    character(len=:), allocatable :: restart_changes
    type(path_t), allocatable :: checkpoints(:)  !! written by this run (and the one resumed)
  end type simulation_t

end module dkt_run_state

!> The solver's state of one run: the configuration and lattice parameters, the slab, the
!> boundaries, the two lattices, the particles, the window, the pair's diagnostics and the step.
!> The services keep their own state (dkt_output output_t, dkt_checkpoint_policy
!> checkpoint_state_t) and read this one; a separate module so that they need not use the loop's.
module dkt_run_state
  use dkt_config, only: config_t, lattice_params_t
  use dkt_mrt, only: collision_t, sweep_t
  use dkt_domain, only: domain_t
  use dkt_boundary, only: boundary_t
  use dkt_particles, only: particles_t
  use dkt_links, only: links_t
  use dkt_window, only: window_t
  use dkt_diagnostics, only: pair_diag_t
  use dkt_store, only: lattice_t
  use dkt_kinds, only: wp, i8
  implicit none
  private
  public :: simulation_t

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
    type(links_t) :: links          !! their boundary links (allocated with them)
    logical :: particles_on = .false.
    logical :: particles_move = .false. !! some particle is free or prescribed
    !> the contact sub-steps taken instead of collision.substeps, for the start-up summary's
    !! note ('' when the setting was kept)
    character(len=:), allocatable :: substep_note
    type(window_t) :: win           !! used only when the scene asks for a window
    logical :: window_on = .false.
    type(pair_diag_t) :: pair       !! particles 1 and 2, when the scene has two or more
    logical :: pair_on = .false.
    !> centre and radius of particles 1 and 2 after the last step (x, y, r; the pair diagnostics)
    real(wp) :: pair_v(3, 2) = 0.0_wp
    !> the particle speed guard's failure after the last step, '' if none (the same everywhere)
    character(len=:), allocatable :: fast
    integer :: step = 0
    !> lattice-node updates this process has made (nx*ny a step, more once a window grew): the
    !! speed the progress and performance lines report
    integer(i8) :: updates = 0
    character(len=:), allocatable :: stopped_early !! why the run ended before its last step
    !> the interior nodes of the disks have not been reset after the last step (nothing in a
    !! step reads them): simulation_settle resets them before anything reads the lattice
    logical :: interior_due = .false.
    !> the fewest rows a slab may hold (the particles' reach: dkt_simulation's set-up), which a
    !! balanced split keeps
    integer :: min_rows = 2
    !> a balance check found no split better than the present one: said once in the log
    logical :: balance_noted = .false.
    logical :: balance_checked = .false. !! a balance check was made in this run
  end type simulation_t

end module dkt_run_state

!> Working precision, integer kinds, the matching MPI datatype and physical constants.
module dkt_kinds
  use iso_fortran_env, only: real32, real64, int32, int64
  use mpi_f08, only: MPI_Datatype, MPI_DOUBLE_PRECISION
  implicit none
  private
  public :: wp, sp, ip, i8, mpi_wp, pi, cs2, MAX_PARTICLES

  integer, parameter :: wp = real64 !! working precision of every field and particle quantity
  integer, parameter :: sp = real32 !! populations with lbm.precision = 'single' (and its arithmetic
  !! with 'single_arith' and 'half')
  integer, parameter :: ip = int32  !! default integer kind for indices
  integer, parameter :: i8 = int64  !! counters that may exceed 2**31 (cell updates, bytes)
  type(MPI_Datatype), parameter :: mpi_wp = MPI_DOUBLE_PRECISION !! MPI type matching wp

  real(wp), parameter :: pi = 3.14159265358979323846264338327950288_wp
  !> lattice speed of sound squared, c_s^2 (docs/model.md §1)
  real(wp), parameter :: cs2 = 1.0_wp/3.0_wp

  !> The most particles a scene may hold: a checkpoint holds at most this many (dkt_checkpoint
  !! refuses a larger count as damaged), so a run with more could not be resumed.
  integer, parameter :: MAX_PARTICLES = 1000000
end module dkt_kinds

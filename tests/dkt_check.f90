!> The checks of the Fortran test programs: each prints PASS or FAIL with its name and a
!> number that shows how close it came, and the program ends with `N passed, M failed` and a
!> non-zero exit status when any failed.
module dkt_check
  use dkt_kinds, only: wp
  implicit none
  private
  public :: check, finish

  integer, save :: passed = 0, failed = 0

contains

  subroutine check(name, ok, detail)
    character(len=*), intent(in) :: name !! what the check proves
    logical, intent(in) :: ok
    real(wp), intent(in) :: detail       !! the measured error or value
    if (ok) then
      passed = passed + 1
      write (*, '(a,a,es11.3)') 'PASS ', name, detail
    else
      failed = failed + 1
      write (*, '(a,a,es11.3)') 'FAIL ', name, detail
    end if
  end subroutine check

  subroutine finish()
    write (*, '(i0,a,i0,a)') passed, ' passed, ', failed, ' failed'
    if (failed > 0) error stop 1
  end subroutine finish

end module dkt_check

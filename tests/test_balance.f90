!> Unit tests of the balanced split of the rows over the ranks (dkt_balance):
!>  - on 300 random cost profiles (20-40 rows, 2-4 ranks, slabs of at least 1-6 rows, some rows
!>    costing 100 times the others, as a slab of disks does against the fluid), balance_split
!>    gives slabs that tile the rows, each at least min_rows long, whose costliest slab costs no
!>    more than the best split that a search over every split finds (to a part in 10^9);
!>  - a uniform cost gives no slab longer than the even split's longest;
!>  - balance_imbalance is 1 for a perfect split and the costliest slab over the mean otherwise.
program test_balance
  use dkt_kinds, only: wp
  use dkt_check, only: check, finish
  use dkt_balance, only: balance_split, balance_imbalance
  implicit none
  integer :: trial, ny, n, m, worst_rows
  real(wp) :: u, best, got, worst_gap
  real(wp), allocatable :: cost(:)
  integer, allocatable :: starts(:)
  logical :: tiles, long_enough, optimal

  call random_seed(put=[(4242 + 7*trial, trial=1, 64)])
  tiles = .true.
  long_enough = .true.
  optimal = .true.
  worst_gap = 0.0_wp
  do trial = 1, 300
    call random_number(u)
    ny = 20 + int(21*u)
    call random_number(u)
    n = 2 + int(3*u)
    call random_number(u)
    m = 1 + int(6*u)
    if (n*m > ny) m = ny/n
    allocate (cost(ny))
    call random_number(cost)
    where (cost > 0.8_wp) cost = 100.0_wp*cost
    cost = cost + 1.0_wp
    allocate (starts(0:n))
    starts = balance_split(cost, n, m)
    tiles = tiles .and. starts(0) == 0 .and. starts(n) == ny .and. &
            all(starts(1:n) > starts(0:n - 1))
    long_enough = long_enough .and. all(starts(1:n) - starts(0:n - 1) >= m)
    got = costliest(cost, starts)
    best = best_split(cost, n, m)
    worst_gap = max(worst_gap, got/best - 1.0_wp)
    optimal = optimal .and. got <= best*(1.0_wp + 1.0e-9_wp)
    deallocate (cost, starts)
  end do
  call check('balance: the slabs tile the rows', tiles, 0.0_wp)
  call check('balance: every slab holds at least min_rows rows', long_enough, 0.0_wp)
  call check('balance: the costliest slab costs what the best split''s does', optimal, worst_gap)

  allocate (cost(101))
  cost = 1.0_wp
  allocate (starts(0:4))
  starts = balance_split(cost, 4, 2)
  worst_rows = maxval(starts(1:4) - starts(0:3))
  call check('balance: a uniform cost of 101 rows on 4 ranks: no slab over 26 rows', &
             worst_rows == 26, real(worst_rows, wp))
  call check('balance: an even split of a uniform cost has imbalance 1', &
             abs(balance_imbalance([1.0_wp, 1.0_wp, 1.0_wp, 1.0_wp], [0, 2, 4]) - 1.0_wp) &
             < 1.0e-15_wp, 0.0_wp)
  call check('balance: the imbalance is the costliest slab over the mean', &
             abs(balance_imbalance([3.0_wp, 1.0_wp, 1.0_wp, 1.0_wp], [0, 1, 4]) - 1.0_wp) &
             < 1.0e-15_wp .and. &
             abs(balance_imbalance([3.0_wp, 1.0_wp, 1.0_wp, 1.0_wp], [0, 2, 4]) - 4.0_wp/3.0_wp) &
             < 1.0e-15_wp, 0.0_wp)
  call finish()

contains

  !> The costliest slab of the split
  pure real(wp) function costliest(cost, starts) result(c)
    real(wp), intent(in) :: cost(:)
    integer, intent(in) :: starts(0:)
    integer :: r
    c = 0.0_wp
    do r = 0, size(starts) - 2
      c = max(c, sum(cost(starts(r) + 1:starts(r + 1))))
    end do
  end function costliest

  !> The least costliest slab over every split of the rows into n slabs of at least m rows
  !! (a recursion over the first border)
  recursive real(wp) function best_split(cost, n, m) result(best)
    real(wp), intent(in) :: cost(:)
    integer, intent(in) :: n, m
    integer :: j
    if (n == 1) then
      best = sum(cost)
      return
    end if
    best = huge(1.0_wp)
    do j = m, size(cost) - (n - 1)*m
      best = min(best, max(sum(cost(1:j)), best_split(cost(j + 1:), n - 1, m)))
    end do
  end function best_split
end program test_balance

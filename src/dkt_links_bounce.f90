!> The boundary links of the particles a slab holds (docs/model.md §3): the exact circle
!> intersection, curved bounce-back (E6: halfway, Yu, BFL), the momentum exchange of each link
!> (E7, and the Galilean-invariant variant) summed per particle and row, the nodes inside the
!> disks and those a moving disk uncovers.
!>
!> Interior nodes (coupling.interior): 'solid', they are not fluid: after a sweep they hold
!> the equilibrium at the local particle velocity (written when the lattice is read:
!> links_interior_after_move), and a node the particle uncovers is refilled
!> with the equilibrium at the wall velocity and the mean density of its fluid neighbours.
!> 'fluid', they hold fluid that streams and collides like the rest, bounced back from the inside
!> of the surface on the interior links; nothing is reset or refilled.
!>
!> Every population these routines read or write goes through its unshifted 8-byte value
!> (dkt_store), whatever lbm.precision stores: bounce-back with a moving wall, the equilibria
!> and the density sums are point-wise physics, computed in 8 bytes. The work is that of the
!> links and nodes of the disks a slab holds: nothing here loops over rows without links or over
!> particles the slab does not hold.
submodule(dkt_links) dkt_links_bounce
  use iso_fortran_env, only: int16
  use dkt_kinds, only: wp, sp, i8, cs2
  use dkt_choices, only: BB_HALFWAY, BB_YU, BB_BFL
  use dkt_lattice, only: ex, ey, w, opp, equilibrium
  use dkt_domain, only: domain_t, domain_edge_rows
  use dkt_store, only: lattice_t, lattice_get, lattice_set, lattice_get_node, lattice_set_node
  use dkt_half, only: half_encode, half_decode
  use dkt_errors, only: internal_error
  use dkt_text, only: itoa
  use dkt_link_geometry, only: link_fraction, link_fractions
  use dkt_particle_state, only: particle_state_t
  implicit none

  !> One disk copied out of the state (disk): what the loops over its nodes read, in scalars
  type :: disk_t
    real(wp) :: x = 0, y = 0, r = 0      !! centre, radius
    real(wp) :: u = 0, v = 0, omega = 0  !! velocity, angular velocity
  end type disk_t

contains

  !> The rigid-body velocity U + Omega x (x - X) of disk p at the point (px, py).
  pure subroutine surface_velocity(p, px, py, ux, uy)
    type(disk_t), intent(in) :: p
    real(wp), intent(in) :: px, py
    real(wp), intent(out) :: ux, uy
    ux = p%u - p%omega*(py - p%y)
    uy = p%v + p%omega*(px - p%x)
  end subroutine surface_velocity

  !> Disk k of s, copied out of the arrays for the loops over its nodes.
  pure type(disk_t) function disk(s, k) result(p)
    type(particle_state_t), intent(in) :: s
    integer, intent(in) :: k
    p = disk_t(s%x(k), s%y(k), s%r(k), s%u(k), s%v(k), s%omega(k))
  end function disk

  !> Whether the point (px, py) lies strictly inside disk p.
  pure logical function inside(p, px, py)
    type(disk_t), intent(in) :: p
    real(wp), intent(in) :: px, py
    inside = (px - p%x)**2 + (py - p%y)**2 < p%r**2
  end function inside

  !> The wall point x_w = x_f + q e_d of the link from node (i, jg) (global row) along e_d, the
  !! rigid-body velocity u_w there and the moving-wall term W = -2 w_d rho (e_d . u_w)/c_s^2 of
  !! the population bounced back towards x_f. The interior side of the same link receives -W.
  pure subroutine wall_of_link(p, i, jg, d, q, rho, xw, yw, uwx, uwy, wall)
    type(disk_t), intent(in) :: p
    integer, intent(in) :: i, jg, d
    real(wp), intent(in) :: q, rho
    real(wp), intent(out) :: xw, yw, uwx, uwy, wall
    xw = i - 0.5_wp + q*ex(d)
    yw = jg - 0.5_wp + q*ey(d)
    call surface_velocity(p, xw, yw, uwx, uwy)
    wall = -2.0_wp*w(d)*rho*(ex(d)*uwx + ey(d)*uwy)/cs2
  end subroutine wall_of_link

  !> The density at node (i, j) of this slab, summed as every routine here sums it.
  real(wp) function node_density(f, i, j) result(rho)
    type(lattice_t), intent(in) :: f
    integer, intent(in) :: i, j
    rho = sum(lattice_get_node(f, i, j))
  end function node_density

  module subroutine links_find(lk, ps, dom)
    type(links_t), intent(inout) :: lk
    type(particles_t), intent(in) :: ps
    type(domain_t), intent(in) :: dom
    integer :: k
    call search_links(lk, ps, dom)
    call link_fractions(lk%nlinks, lk%lp, lk%lx, lk%ly, lk%ld, dom%y0, ps%p%x, ps%p%y, ps%p%r, &
                        lk%lq)
    lk%ninner = 0
    if (.not. lk%fluid_interior) return
    do k = 1, ps%n
      call inner_links_of(lk, ps, dom, k)
    end do
  end subroutine links_find

  !> The interior links of disk k (coupling.interior = 'fluid'), in the order of its nodes (row,
  !! column): those of its nodes within 1.5 of the surface (a node deeper has every neighbour
  !! inside k too), each node of k's runs being a node inside k (and so not fluid).
  subroutine inner_links_of(lk, ps, dom, k)
    type(links_t), intent(inout) :: lk
    type(particles_t), intent(in) :: ps
    type(domain_t), intent(in) :: dom
    integer, intent(in) :: k
    integer :: j, i, lo, hi
    real(wp) :: px, py, dist2, near2, deep2
    near2 = (ps%p%r(k) + 1.5_wp)**2
    deep2 = max(ps%p%r(k) - 1.5_wp, 0.0_wp)**2
    do j = max(1, lk%span_j0(k)), min(dom%nyl, lk%span_j0(k) + lk%span_nj(k) - 1)
      lo = lk%span(1, j - lk%span_j0(k) + 1, k)
      hi = lk%span(2, j - lk%span_j0(k) + 1, k)
      py = dom%y0 + j - 0.5_wp
      do i = max(1, lo), min(dom%nx, hi)
        px = i - 0.5_wp
        dist2 = (px - ps%p%x(k))**2 + (py - ps%p%y(k))**2
        if (dist2 >= near2 .or. dist2 < deep2) cycle
        call add_inner_links(lk, ps, dom, k, i, j)
      end do
    end do
  end subroutine inner_links_of

  !> Append the interior links of node (i, j) of this slab, which lies inside particle k
  !! (coupling.interior = 'fluid'): each direction i with x_f = x_s - e_i outside k and a
  !! lattice node (a fluid node, a halo node or a node of another particle; not beyond a side
  !! or a closed end). q is computed from x_f as for the boundary link (x_f, i), so that both
  !! sides of the link take the wall point, and u_w there, with the same bits.
  subroutine add_inner_links(lk, ps, dom, k, i, j)
    type(links_t), intent(inout) :: lk
    type(particles_t), intent(in) :: ps
    type(domain_t), intent(in) :: dom
    integer, intent(in) :: k, i, j
    type(inner_link_t), allocatable :: grown(:)
    integer :: d, fi, fjg, m
    do d = 1, 8
      fi = i - ex(d)
      fjg = dom%y0 + j - ey(d)
      ! x_f inside k: in k's run of its row (rows 0..nyl+1, columns 0..nx+1)
      m = j - ey(d) - lk%span_j0(k) + 1
      if (m >= 1 .and. m <= lk%span_nj(k)) then
        if (fi >= lk%span(1, m, k) .and. fi <= lk%span(2, m, k)) cycle
      end if
      if (fi < 1 .or. fi > dom%nx) cycle
      if (.not. dom%periodic_y .and. (fjg < 1 .or. fjg > dom%ny)) cycle
      if (lk%ninner == size(lk%inner)) then
        allocate (grown(max(64, 2*lk%ninner)))
        grown(1:lk%ninner) = lk%inner(1:lk%ninner)
        call move_alloc(grown, lk%inner)
      end if
      lk%ninner = lk%ninner + 1
      lk%inner(lk%ninner) = inner_link_t(k, i, j, d, &
                                         link_fraction(ps%p%x(k), ps%p%y(k), ps%p%r(k), &
                                                       fi - 0.5_wp, fjg - 0.5_wp, d), &
                                         is_fluid(lk, ps, dom, fi, fjg), 0.0_wp)
    end do
  end subroutine add_inner_links

  module subroutine links_inner_save(lk, ps, dom, f)
    type(links_t), intent(inout) :: lk
    type(particles_t), intent(in) :: ps
    type(domain_t), intent(in) :: dom
    type(lattice_t), intent(in) :: f
    integer :: l, i, j, d, fi, fj
    real(wp) :: rho, xw, yw, uwx, uwy, wall
    do i = 1, dom%nx
      lk%rho_first(i) = node_density(f, i, 1)
      lk%rho_last(i) = node_density(f, i, dom%nyl)
    end do
    call domain_edge_rows(dom, lk%rho_first, lk%rho_last, lk%rho_below, lk%rho_above)
    do l = 1, lk%ninner
      i = lk%inner(l)%i
      j = lk%inner(l)%j
      d = lk%inner(l)%d
      fi = i - ex(d)
      fj = j - ey(d)
      rho = 1.0_wp
      if (lk%inner(l)%ff) then
        if (fj == 0) then
          rho = lk%rho_below(fi)
        else if (fj == dom%nyl + 1) then
          rho = lk%rho_above(fi)
        else
          rho = node_density(f, fi, fj)
        end if
      end if
      call wall_of_link(disk(ps%p, lk%inner(l)%k), fi, dom%y0 + fj, d, lk%inner(l)%q, rho, xw, yw, &
                        uwx, uwy, wall)
      lk%inner(l)%val = lattice_get(f, i, j, opp(d)) - wall
    end do
  end subroutine links_inner_save

  module subroutine links_inner_write(lk, f)
    type(links_t), intent(in) :: lk
    type(lattice_t), intent(inout) :: f
    integer :: l
    do l = 1, lk%ninner
      associate (a => lk%inner(l))
        call lattice_set(f, a%i - ex(a%d), a%j - ey(a%d), a%d, a%val)
      end associate
    end do
  end subroutine links_inner_write

  module subroutine links_bounce(lk, ps, dom, f, j1, j2)
    type(links_t), intent(inout) :: lk
    type(particles_t), intent(in) :: ps
    type(domain_t), intent(in) :: dom
    type(lattice_t), intent(inout) :: f
    integer, intent(in) :: j1, j2 !! rows of the fluid nodes whose links are bounced
    real(wp) :: no_d(1)
    real(sp) :: no_s(1)
    integer(int16) :: no_h(1)
    integer :: l, m1, n
    if (j2 < j1) return
    do l = 1, lk%nrows
      if (lk%rj(l) >= j1 .and. lk%rj(l) <= j2) lk%rows(:, l) = 0.0_wp
    end do
    m1 = lk%lstart(max(j1, 1))
    n = lk%lstart(min(j2, dom%nyl) + 1) - m1
    if (n <= 0) return
    select case (lk%scheme)
    case (BB_YU, BB_BFL, BB_HALFWAY)
    case default
      call internal_error('links_bounce: bounce-back code '//itoa(lk%scheme))
    end select
    ! the links row by row (lk%lorder), each row's in their order (particle, column,
    ! direction): the lattice is read and written along its rows, and each row sum still adds
    ! its links in their order. A link reads only fluid nodes and writes only a solid slot that
    ! no other link reads, so each link can write its result as soon as it has it. The loop
    ! reads and writes the stored array of the lattice's storage; the other one is a stand-in
    ! that it never touches.
    if (f%half) then
      call bounce_links(ps%p, lk%scheme, lk%galilean, dom%y0, lk%lorder(m1:m1 + n - 1), no_d, &
                        no_s, f%h, size(f%h, 1), size(f%h, 2), .false., .false., .true., lk%lp, &
                        lk%lx, lk%ly, lk%ld, lk%lq, lk%lff, lk%lrow, lk%rows)
    else if (.not. f%single) then
      call bounce_links(ps%p, lk%scheme, lk%galilean, dom%y0, lk%lorder(m1:m1 + n - 1), f%d, &
                        no_s, no_h, size(f%d, 1), size(f%d, 2), .false., .false., .false., &
                        lk%lp, lk%lx, lk%ly, lk%ld, lk%lq, lk%lff, lk%lrow, lk%rows)
    else
      call bounce_links(ps%p, lk%scheme, lk%galilean, dom%y0, lk%lorder(m1:m1 + n - 1), no_d, &
                        f%s, no_h, size(f%s, 1), size(f%s, 2), .true., f%shifted, .false., &
                        lk%lp, lk%lx, lk%ly, lk%ld, lk%lq, lk%lff, lk%lrow, lk%rows)
    end if
  end subroutine links_bounce

  !> Where a link along e_i reads and writes, as offsets from population 0 of its fluid node
  !! x_f in a lattice f(0:nxp-1, 0:ny-1, 0:8) taken as one array (f(x, j, i) is element
  !! x + nxp j + nxp ny i, counted from 0): f_i at x_f (own), f_ibar at x_f (back), f_i at
  !! x_f - e_i (behind), and the slot f_ibar of the solid node x_f + e_i (ahead).
  pure subroutine link_offsets(nxp, ny, own, back, behind, ahead)
    integer(i8), intent(in) :: nxp, ny
    integer(i8), intent(out) :: own(0:8), back(0:8), behind(0:8), ahead(0:8)
    integer :: i
    do i = 0, 8
      own(i) = i*nxp*ny
      back(i) = opp(i)*nxp*ny
      behind(i) = own(i) - ex(i) - nxp*ey(i)
      ahead(i) = back(i) + ex(i) + nxp*ey(i)
    end do
  end subroutine link_offsets

  !> links_bounce on the links order(:), on the populations as the lattice stores them
  !! (dkt_store), f(0:nxp-1, 0:ny-1, 0:8) taken as one array: fd in 8 bytes, fs in 4
  !! (single) holding f_i - w_i (shifted) or f_i, or fh in 16-bit codes of f_i - w_i (half).
  !! Each value is read and written as
  !! lattice_get and lattice_set do, unshifted in 8 bytes. The density at x_f is summed once
  !! for the links of a node that follow one another, the disk copied once for the links of a
  !! disk that do. The link arrays of particles_t and its row sums come one by one, as arrays
  !! of their own, so that the loop holds their addresses instead of reading them out of the
  !! derived type at each link.
  subroutine bounce_links(p, scheme, galilean, y0, order, fd, fs, fh, nxp, ny, single, shifted, &
                          half, lp, lx, ly, ld, lq, lff, lrow, rows)
    type(particle_state_t), intent(in) :: p !! the disks
    integer, intent(in) :: scheme !! BB_YU, BB_BFL or BB_HALFWAY
    logical, intent(in) :: galilean !! E7 with e - u_w
    integer, intent(in) :: y0 !! global row of local row 0
    integer, intent(in) :: order(:) !! the links, in the order they are bounced
    real(wp), intent(inout) :: fd(0:*)
    real(sp), intent(inout) :: fs(0:*)
    integer(int16), intent(inout) :: fh(0:*)
    integer, intent(in) :: nxp, ny
    logical, intent(in) :: single, shifted, half
    integer, intent(in) :: lp(*), lx(*), ly(*), ld(*), lrow(*) !! particles_t's lp, ...
    real(wp), intent(in) :: lq(*)
    logical, intent(in) :: lff(*)
    real(wp), intent(inout) :: rows(3, *) !! particles_t's rows
    integer(i8) :: own(0:8), back(0:8), behind(0:8), ahead(0:8), nx8, np8, o, olast
    integer :: t, l, i, k, kp, d
    real(wp) :: q, fi, fib, fff, rho, fb, uwx, uwy, wall, xw, yw, fx, fy
    type(disk_t) :: pk
    nx8 = nxp
    np8 = nx8*ny
    call link_offsets(nx8, int(ny, i8), own, back, behind, ahead)
    kp = 0
    olast = -1
    rho = 0.0_wp
    do t = 1, size(order)
      l = order(t)
      d = ld(l)
      q = lq(l)
      o = lx(l) + nxp*ly(l)
      ! f_i and f_ibar at x_f, f_i at x_f - e_i (read by Yu and BFL only when it is a fluid
      ! node, x_f's own otherwise: then it is not used), the density at x_f
      if (half) then
        fi = real(half_decode(fh(o + own(d))), wp) + w(d)
        fib = real(half_decode(fh(o + back(d))), wp) + w(opp(d))
        fff = fi
        if (lff(l)) fff = real(half_decode(fh(o + behind(d))), wp) + w(d)
        if (o /= olast) then
          rho = 0.0_wp
          do i = 0, 8
            rho = rho + (real(half_decode(fh(o + i*np8)), wp) + w(i))
          end do
        end if
      else if (.not. single) then
        fi = fd(o + own(d))
        fib = fd(o + back(d))
        fff = fi
        if (lff(l)) fff = fd(o + behind(d))
        if (o /= olast) then
          rho = 0.0_wp
          do i = 0, 8
            rho = rho + fd(o + i*np8)
          end do
        end if
      else
        fi = real(fs(o + own(d)), wp)
        fib = real(fs(o + back(d)), wp)
        fff = fi
        if (lff(l)) fff = real(fs(o + behind(d)), wp)
        if (shifted) then
          fi = fi + w(d)
          fib = fib + w(opp(d))
          fff = fff + w(d)
        end if
        if (o /= olast) then
          rho = 0.0_wp
          if (shifted) then
            do i = 0, 8
              rho = rho + (real(fs(o + i*np8), wp) + w(i))
            end do
          else
            do i = 0, 8
              rho = rho + real(fs(o + i*np8), wp)
            end do
          end if
        end if
      end if
      olast = o
      k = lp(l)
      if (k /= kp) then
        pk = disk(p, k)
        kp = k
      end if
      ! wall point, its velocity u_w = U + Omega x (x_w - X) and the moving-wall term
      call wall_of_link(pk, lx(l), y0 + ly(l), d, q, rho, xw, yw, uwx, uwy, wall)
      select case (scheme)
      case (BB_YU)
        if (lff(l)) then
          fb = ((1.0_wp - q)*fff + q*fi + q*fib + wall)/(1.0_wp + q)
        else
          fb = fi + wall
        end if
      case (BB_BFL)
        if (q < 0.5_wp) then
          if (lff(l)) then
            fb = 2.0_wp*q*fi + (1.0_wp - 2.0_wp*q)*fff + wall
          else
            fb = fi + wall
          end if
        else
          fb = (fi + (2.0_wp*q - 1.0_wp)*fib + wall)/(2.0_wp*q)
        end if
      case default
        fb = fi + wall
      end select
      ! f_ibar(x_f, t+1) into the solid slot x_f + e_i
      if (half) then
        fh(o + ahead(d)) = half_encode(real(fb - w(opp(d)), sp))
      else if (.not. single) then
        fd(o + ahead(d)) = fb
      else if (shifted) then
        fs(o + ahead(d)) = real(fb - w(opp(d)), sp)
      else
        fs(o + ahead(d)) = real(fb, sp)
      end if
      ! E7: F_i = e_i f_i* - e_ibar f_ibar(t+1) = e_i (f_i* + f_ibar), taken against the rest
      ! state (f_i = w_i): the uniform rest pressure rho_0 c_s^2 adds exactly nothing to a disk
      ! that fluid surrounds, but where a disk's nodes border a wall or another disk with no
      ! fluid between, their links are missing and it would press the disk there with
      ! rho_0 c_s^2 per spacing, hundreds of times a light disk's weight (docs/stability.md).
      ! The Galilean-invariant form replaces e by e - u_w (its u_w term holds no rest part).
      fx = ex(d)*(fi + fb - 2.0_wp*w(d))
      fy = ey(d)*(fi + fb - 2.0_wp*w(d))
      if (galilean) then
        fx = fx - uwx*(fi - fb)
        fy = fy - uwy*(fi - fb)
      end if
      associate (e => lrow(l))
        rows(1, e) = rows(1, e) + fx
        rows(2, e) = rows(2, e) + fy
        rows(3, e) = rows(3, e) + (xw - pk%x)*fy - (yw - pk%y)*fx
      end associate
    end do
  end subroutine bounce_links

  module subroutine links_interior(lk, ps, dom, f)
    type(links_t), intent(inout) :: lk
    type(particles_t), intent(in) :: ps
    type(domain_t), intent(in) :: dom
    type(lattice_t), intent(inout) :: f
    call reset_disks(ps%p, ps%n, dom, f, lk%nodes_reset)
    lk%resets = lk%resets + 1
  end subroutine links_interior

  module subroutine links_interior_after_move(lk, ps, dom, f)
    type(links_t), intent(inout) :: lk
    type(particles_t), intent(in) :: ps
    type(domain_t), intent(in) :: dom
    type(lattice_t), intent(inout) :: f
    call place_for_nodes(lk, ps, dom)
    call reset_disks(ps%old, ps%nold, dom, f, lk%nodes_reset, lk%solid)
    lk%resets = lk%resets + 1
  end subroutine links_interior_after_move

  !> The equilibrium at density 1 and the rigid-body velocity of disk k of s at every node
  !! inside it, disk after disk (the later disk's where two overlap); with `solid` only at the
  !! nodes it marks. `nodes` counts the nodes written.
  subroutine reset_disks(s, n, dom, f, nodes, solid)
    type(particle_state_t), intent(in) :: s
    integer, intent(in) :: n
    type(domain_t), intent(in) :: dom
    type(lattice_t), intent(inout) :: f
    integer(i8), intent(inout) :: nodes
    logical, intent(in), optional :: solid(1:, 0:)
    integer :: k, i, j, jg, i1, i2, j1, j2
    real(wp) :: px, py, ux, uy
    type(disk_t) :: pk
    do k = 1, n
      pk = disk(s, k)
      call box(pk, dom, i1, i2, j1, j2)
      do j = j1, j2
        jg = dom%y0 + j
        do i = i1, i2
          px = i - 0.5_wp
          py = jg - 0.5_wp
          if (.not. inside(pk, px, py)) cycle
          if (present(solid)) then
            if (.not. solid(i, j)) cycle
          end if
          call surface_velocity(pk, px, py, ux, uy)
          call lattice_set_node(f, i, j, equilibrium(1.0_wp, ux, uy))
          nodes = nodes + 1
        end do
      end do
    end do
  end subroutine reset_disks

  module subroutine links_refill(lk, ps, dom, f)
    type(links_t), intent(inout) :: lk
    type(particles_t), intent(in) :: ps
    type(domain_t), intent(in) :: dom
    type(lattice_t), intent(inout) :: f
    integer :: k, m, i, j, jg, d, nf, oj0, onj, lo, hi, nlo, nhi
    integer, allocatable :: found(:, :)
    real(wp) :: px, py, rho, ux, uy
    type(disk_t) :: po, pk
    ! interior fluid (coupling.interior = 'fluid'): an uncovered node already holds fluid
    if (lk%fluid_interior) return
    call place_for_nodes(lk, ps, dom)
    m = 1
    do k = 1, ps%n
      do while (m <= ps%nold)
        if (ps%old%id(m) >= ps%p%id(k)) exit
        m = m + 1
      end do
      if (m > ps%nold) exit
      if (ps%old%id(m) /= ps%p%id(k)) cycle
      ! the old disk and the new one
      po = disk(ps%old, m)
      pk = disk(ps%p, k)
      ! (a disk of radius r covers at most 2 r + 3 rows)
      onj = int(min(2.0_wp*po%r, 1.0e6_wp)) + 4
      if (allocated(found)) then
        if (size(found, 2) < onj) deallocate (found)
      end if
      if (.not. allocated(found)) allocate (found(2, onj))
      if (old_spans_of(lk, dom, m, po%x, po%y, po%r)) then
        oj0 = lk%span_j0_old(m)
        onj = lk%span_nj_old(m)
        found(:, 1:onj) = lk%span_old(:, 1:onj, m)
      else
        call disk_spans(po%x, po%y, po%r, dom, oj0, onj, found)
      end if
      do j = max(1, oj0), min(dom%nyl, oj0 + onj - 1)
        lo = found(1, j - oj0 + 1)
        hi = found(2, j - oj0 + 1)
        ! the run of the new disk in this row (none: nlo > nhi)
        nlo = 1
        nhi = 0
        if (j >= lk%span_j0(k) .and. j < lk%span_j0(k) + lk%span_nj(k)) then
          nlo = lk%span(1, j - lk%span_j0(k) + 1, k)
          nhi = lk%span(2, j - lk%span_j0(k) + 1, k)
        end if
        jg = dom%y0 + j
        py = jg - 0.5_wp
        i = max(1, lo)
        do while (i <= min(dom%nx, hi))
          ! inside the new disk too: not fluid
          if (i >= nlo .and. i <= nhi) then
            i = nhi + 1
            cycle
          end if
          px = i - 0.5_wp
          if (is_fluid(lk, ps, dom, i, jg)) then
            ! mean density of the fluid neighbours in the same row: a row is never split
            ! between ranks, so the refill does not depend on the decomposition
            rho = 0.0_wp
            nf = 0
            do d = 1, 3, 2
              ! a neighbour inside the old disk is in its run
              if (i + ex(d) >= lo .and. i + ex(d) <= hi) cycle
              if (.not. is_fluid(lk, ps, dom, i + ex(d), jg)) cycle
              rho = rho + sum(lattice_get_node(f, i + ex(d), j))
              nf = nf + 1
            end do
            if (nf > 0) then
              rho = rho/nf
            else
              rho = 1.0_wp
            end if
            call surface_velocity(pk, px, py, ux, uy)
            call lattice_set_node(f, i, j, equilibrium(rho, ux, uy))
          end if
          i = i + 1
        end do
      end do
    end do
  end subroutine links_refill

  !> Rows j1..j2 and columns i1..i2 of this slab that a disk can touch, with a margin of two
  !! nodes for the links and their second fluid nodes.
  pure subroutine box(p, dom, i1, i2, j1, j2)
    type(disk_t), intent(in) :: p
    type(domain_t), intent(in) :: dom
    integer, intent(out) :: i1, i2, j1, j2
    i1 = max(1, floor(p%x - p%r) - 2)
    i2 = min(dom%nx, ceiling(p%x + p%r) + 2)
    j1 = max(1, floor(p%y - p%r) - 2 - dom%y0)
    j2 = min(dom%nyl, ceiling(p%y + p%r) + 2 - dom%y0)
  end subroutine box

  module subroutine particles_solid_field(ps, dom, id)
    type(particles_t), intent(in) :: ps
    type(domain_t), intent(in) :: dom
    real(wp), intent(out) :: id(:, :)
    integer :: k, i, j, i1, i2, j1, j2
    id = 0.0_wp
    do k = 1, ps%n
      call box(disk(ps%p, k), dom, i1, i2, j1, j2)
      do j = j1, j2
        do i = i1, i2
          if (inside(disk(ps%p, k), i - 0.5_wp, dom%y0 + j - 0.5_wp)) &
            id(i, j) = ps%p%id(k)
        end do
      end do
    end do
  end subroutine particles_solid_field
end submodule dkt_links_bounce

!> The checks a checkpoint's state must pass before a run resumes from it, beyond those of
!> checkpoint_read (shapes, digests, finite values): against the scene and against the run file
!> the resumed run continues. Each is a named function returning what is wrong ('' if nothing),
!> the same on every rank: every rank holds the same state and reads the same files. They run
!> before the run file is cut back, so a refused checkpoint leaves every file as it was.
module dkt_restart_check
  use ieee_arithmetic, only: ieee_is_finite
  use mpi_f08, only: MPI_Allreduce, MPI_LOGICAL, MPI_LAND
  use hdf5, only: hsize_t
  use dkt_kinds, only: wp, i8
  use dkt_checkpoint, only: checkpoint_t
  use dkt_run_state, only: simulation_t
  use dkt_window, only: window_t, window_offset
  use dkt_h5file, only: io_file_t, io_file_open, io_file_close, io_get_real, io_dataset_dims, &
                        io_file_attribute
  use dkt_text, only: itoa, fmt_real
  implicit none
  private
  public :: restart_problem, run_file_problem

contains

  !> What makes the checkpoint `chk`, read from `path`, unfit to resume `sim` ('' if nothing):
  !! its step against its file name, its window shift, its particles, and its sample count
  !! against the run file.
  function restart_problem(sim, chk, path) result(p)
    type(simulation_t), intent(in) :: sim
    type(checkpoint_t), intent(in) :: chk
    character(len=*), intent(in) :: path
    character(len=:), allocatable :: p
    p = step_problem(chk, path)
    if (len(p) == 0 .and. .not. sim%window_on .and. chk%shift /= 0) &
      p = '/state_int holds a window shift of '//itoa(chk%shift)//' rows, but the scene '// &
          'has no window'
    if (len(p) == 0) p = particle_problem(sim, chk)
    if (len(p) == 0) p = series_problem(sim, chk)
  end function restart_problem

  !> Whether the run file the resumed run would continue (<output.dir>/<name>.h5) is the one the
  !! checkpoint's run wrote: both carry the identity drawn when the file was made (/run run_id,
  !! the checkpoint's /run_id). '' if they match, or when either has none (files of an earlier
  !! version) or there is no run file (io_reopen says so).
  function run_file_problem(sim, chk) result(p)
    type(simulation_t), intent(in) :: sim
    type(checkpoint_t), intent(in) :: chk
    character(len=:), allocatable :: p
    type(io_file_t) :: pf
    character(len=:), allocatable :: file, err
    character(len=24) :: a, b
    real(wp) :: id
    logical :: found
    p = ''
    if (chk%run_id == 0.0_wp) return
    if (.not. open_run_file(sim, pf, file)) return
    call io_file_attribute(pf, 'run', 'run_id', id, found)
    call io_file_close(pf, err)
    if (.not. found .or. id == chk%run_id) return
    write (a, '(i0)') int(id, i8)
    write (b, '(i0)') int(chk%run_id, i8)
    p = 'the run file '''//file//''' is another run''s: its /run run_id is '//trim(a)// &
        ', the checkpoint''s run wrote the file with run_id '//trim(b)//'. Resuming would '// &
        'splice this checkpoint onto the other run''s series. Put back the run file of the '// &
        'run that wrote the checkpoint, or resume into another output.dir holding it'
  end function run_file_problem

  !> Open the run file a resumed run continues, <output.dir>/<name>.h5, for reading on every
  !! rank: .false. when some rank does not see it or it is not an HDF5 file (io_reopen refuses
  !! that later, with its message).
  logical function open_run_file(sim, pf, file) result(ok)
    type(simulation_t), intent(in) :: sim
    type(io_file_t), intent(out) :: pf
    character(len=:), allocatable, intent(out) :: file
    character(len=:), allocatable :: err
    logical :: exists
    file = sim%cfg%output_dir//'/'//sim%cfg%name//'.h5'
    inquire (file=file, exist=exists)
    call MPI_Allreduce(exists, ok, 1, MPI_LOGICAL, MPI_LAND, sim%dom%comm)
    if (.not. ok) return
    call io_file_open(pf, file, sim%dom%comm, .false., err)
    ok = len(err) == 0
  end function open_run_file

  !> A checkpoint named <name>_chk_<9 digits>.h5 (checkpoint_name) holds the step of its name.
  function step_problem(chk, path) result(p)
    type(checkpoint_t), intent(in) :: chk
    character(len=*), intent(in) :: path
    character(len=:), allocatable :: p
    integer :: k, named, ios
    p = ''
    k = index(path, '_chk_', back=.true.)
    if (k == 0 .or. len(path) /= k + 16) return
    if (path(k + 14:) /= '.h5' .or. verify(path(k + 5:k + 13), '0123456789') /= 0) return
    read (path(k + 5:k + 13), *, iostat=ios) named
    if (ios /= 0 .or. named == chk%step) return
    p = '/state_int holds step '//itoa(chk%step)//', but the file was written at step '// &
        itoa(named)//' (its name)'
  end function step_problem

  !> Every particle inside the lattice, slower than run.particle_speed_limit, and no two
  !! overlapping deeper than the contact law's range (collision.range, at least one spacing):
  !! E10 pushes a pair apart before it comes that close. Overlaps are found through a grid of
  !! cells of the largest diameter, so the check is linear in the number of particles.
  function particle_problem(sim, chk) result(p)
    type(simulation_t), intent(in) :: sim
    type(checkpoint_t), intent(in) :: chk
    character(len=:), allocatable :: p
    real(wp) :: nx, ny, speed, h, depth, deepest
    integer :: k, m, n, ncx, ncy, cx, cy
    integer, allocatable :: head(:, :), next(:), cell(:, :)
    character(len=200) :: msg
    p = ''
    n = size(chk%particles, 2)
    if (.not. sim%particles_on .or. n == 0) return
    nx = real(sim%lp%nx, wp)
    ny = real(sim%dom%ny, wp)
    do k = 1, n
      associate (v => chk%particles(:, k))
        if (v(1) < 0.0_wp .or. v(1) > nx .or. v(2) < 0.0_wp .or. v(2) > ny) then
          write (msg, '(a,i0,a,es12.5,a,es12.5,a,i0,a,i0,a)') '/particles holds particle ', k, &
            ' at (x, y) = (', v(1), ', ', v(2), ') lattice spacings, outside the lattice of ', &
            sim%lp%nx, ' x ', sim%dom%ny
          p = trim(msg)
          return
        end if
        speed = hypot(v(3), v(4))
        if (speed > sim%cfg%run%particle_speed_limit) then
          write (msg, '(a,i0,a,es12.5,a,es12.5)') '/particles holds particle ', k, ' moving ', &
            speed, ' lattice spacings per step, above run.particle_speed_limit = ', &
            sim%cfg%run%particle_speed_limit
          p = trim(msg)
          return
        end if
      end associate
    end do
    deepest = max(sim%parts%range, 1.0_wp)
    h = max(2.0_wp*maxval(sim%lp%particles%r(1:n)), 1.0_wp)
    ncx = max(1, ceiling(nx/h))
    ncy = max(1, ceiling(ny/h))
    allocate (head(0:ncx - 1, 0:ncy - 1), next(n), cell(2, n))
    head = 0
    do k = n, 1, -1
      cell(:, k) = [min(ncx - 1, int(chk%particles(1, k)/h)), &
                    min(ncy - 1, int(chk%particles(2, k)/h))]
      next(k) = head(cell(1, k), cell(2, k))
      head(cell(1, k), cell(2, k)) = k
    end do
    do k = 1, n
      do cy = max(0, cell(2, k) - 1), min(ncy - 1, cell(2, k) + 1)
        do cx = max(0, cell(1, k) - 1), min(ncx - 1, cell(1, k) + 1)
          m = head(cx, cy)
          do while (m > 0)
            if (m > k) then
              depth = sim%lp%particles%r(k) + sim%lp%particles%r(m) - &
                      hypot(chk%particles(1, k) - chk%particles(1, m), &
                            chk%particles(2, k) - chk%particles(2, m))
              if (depth > deepest) then
                write (msg, '(a,i0,a,i0,a,es12.5,a,es12.5,a)') '/particles holds particles ', &
                  k, ' and ', m, ' overlapping by ', depth, ' lattice spacings, deeper than ', &
                  deepest, ' (collision.range, at least one spacing)'
                p = trim(msg)
                return
              end if
            end if
            m = next(m)
          end do
        end do
      end do
    end do
  end function particle_problem

  !> The checkpoint counts the samples of /particles up to its step: in the run file, the last
  !! one it counts is not after its step and the next one (if any) not before it; a sample at
  !! its step holds its window's offset. A file that lacks the samples is io_reopen's to refuse.
  function series_problem(sim, chk) result(p)
    type(simulation_t), intent(in) :: sim
    type(checkpoint_t), intent(in) :: chk
    character(len=:), allocatable :: p
    type(io_file_t) :: pf
    type(window_t) :: win
    character(len=:), allocatable :: file, err
    integer :: nd, n
    integer(hsize_t) :: dims(3)
    real(wp) :: t(2), t_step, dt, offset(1)
    p = ''
    if (.not. sim%particles_on) then
      if (chk%samples /= 0) p = '/state_int counts '//itoa(chk%samples)//' series samples, '// &
                                'but the scene has no particles'
      return
    end if
    if (chk%samples < 1) then
      p = '/state_int counts no series sample, but a run with particles writes one at step 0'
      return
    end if
    if (.not. open_run_file(sim, pf, file)) return
    call io_dataset_dims(pf, 'particles/t', nd, dims)
    n = int(dims(1))
    if (nd == 1 .and. n >= chk%samples) then
      dt = sim%lp%dt
      t_step = chk%step*dt
      t = t_step
      call io_get_real(pf, 'particles/t', [integer(hsize_t) :: chk%samples - 1], &
                       [integer(hsize_t) :: min(2, n - chk%samples + 1)], t)
      ! sample times are multiples of dt: half a step tells before, at and after apart
      if (.not. all(ieee_is_finite(t))) then
        p = '/particles/t of '''//file//''' holds a time that is not finite at sample '// &
            itoa(chk%samples)//' or after it'
      else if (t(1) > t_step + 0.5_wp*dt .or. t(2) < t_step - 0.5_wp*dt) then
        p = '/state_int counts '//itoa(chk%samples)//' samples of /particles, but in '''// &
            file//''' sample '//itoa(chk%samples)//' is at t = '//fmt_real(t(1))// &
            ' s and the next at t = '//fmt_real(t(2))//' s, while the checkpoint is at step '// &
            itoa(chk%step)//' (t = '//fmt_real(t_step)//' s): the run file would lose '// &
            'samples or repeat them'
      else if (sim%window_on .and. abs(t(1) - t_step) < 0.5_wp*dt) then
        call io_dataset_dims(pf, 'particles/window_offset', nd, dims)
        if (nd == 1 .and. dims(1) >= chk%samples) then
          call io_get_real(pf, 'particles/window_offset', [integer(hsize_t) :: chk%samples - 1], &
                           [1_hsize_t], offset)
          win = sim%win
          win%shift = chk%shift
          if (.not. ieee_is_finite(offset(1))) offset(1) = huge(1.0_wp)
          if (abs(window_offset(win, sim%lp%dx) - offset(1)) > 1.0e-6_wp*sim%lp%dx) &
            p = '/state_int holds a window shift of '//itoa(chk%shift)//' rows (offset '// &
                fmt_real(window_offset(win, sim%lp%dx))//' cm), but /particles/window_offset'// &
                ' of '''//file//''' is '//fmt_real(offset(1))//' cm at the checkpoint''s step'
        end if
      end if
    end if
    call io_file_close(pf, err)
  end function series_problem

end module dkt_restart_check

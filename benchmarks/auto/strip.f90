!----------------------------------------------------------------------------------------
! AUTO-07p equation file: jaxrod's discrete creased strip (inextensible, no gravity),
! symmetric clamp rotation alpha = PAR(1).  Same unknowns and equations as jaxrod:
!
!   U(1:N)   = segment angles theta_i,   U(N+1:N+2) = end force mu = (mu_x, mu_y),
!   F(i)     = dL/dtheta_i = c_{i-1} - c_i + h_i (mu_x sin theta_i - mu_y cos theta_i),
!              c_k = (phi_k - phibar_k) / ell_k,  phi_k = theta_{k+1} - theta_k  (k = 0..N),
!              theta_0 = alpha (left clamp), theta_{N+1} = -alpha (right clamp),
!   F(N+1)   = dL/dmu_x = G - sum_i h_i cos theta_i,
!   F(N+2)   = dL/dmu_y =   - sum_i h_i sin theta_i,
!
! i.e. the gradient of  L = sum_k (phi_k - phibar_k)^2 / (2 ell_k)
!                          - sum_i h_i (mu_x cos theta_i + mu_y sin theta_i) + mu_x G
! (jaxrod/_energy/{bending,geometry,lagrangian}.py with B = 1).  The mesh data h_i, the
! hinge lengths ell_k (half segments at the clamps) and the exact natural turning angles
! phibar_k = theta0(m_{k+1}) - theta0(m_k) are computed by jaxrod.discretize and read
! from mesh.dat; the starting state (alpha = 0) from start.dat.  The Jacobian (DFDU, DFDP)
! is analytic (JAC = 1).  PVLS stores the fold height y(L/2) in PAR(2).
!
! Row scaling (third number on mesh.dat's first line): with scaling = 1 the angle rows are
! multiplied by h_i (same solutions, same folds and branch points).  Unscaled, the Jacobian
! has entries ~ 1/h and its determinant -- AUTO's branch-point test function for algebraic
! problems -- grows like h^-N: ~1e197 at N = 100, overflowing to Inf beyond N ~ 150.
!----------------------------------------------------------------------------------------
MODULE strip_data
  IMPLICIT NONE
  INTEGER :: nseg = 0, scaling = 0
  DOUBLE PRECISION :: gap
  DOUBLE PRECISION, ALLOCATABLE :: h(:), ell(:), pbar(:)
CONTAINS
  SUBROUTINE load_mesh()
    INTEGER :: i, u
    IF (nseg > 0) RETURN
    OPEN(NEWUNIT=u, FILE='mesh.dat', STATUS='OLD', ACTION='READ')
    READ(u, *) nseg, gap, scaling
    ALLOCATE(h(nseg), ell(0:nseg), pbar(0:nseg))
    DO i = 1, nseg
      READ(u, *) h(i)
    END DO
    DO i = 0, nseg
      READ(u, *) ell(i), pbar(i)
    END DO
    CLOSE(u)
  END SUBROUTINE load_mesh
END MODULE strip_data

SUBROUTINE FUNC(NDIM, U, ICP, PAR, IJAC, F, DFDU, DFDP)
  USE strip_data
  IMPLICIT NONE
  INTEGER, INTENT(IN) :: NDIM, ICP(*), IJAC
  DOUBLE PRECISION, INTENT(IN) :: U(NDIM), PAR(*)
  DOUBLE PRECISION, INTENT(OUT) :: F(NDIM)
  DOUBLE PRECISION, INTENT(INOUT) :: DFDU(NDIM, NDIM), DFDP(NDIM, *)
  INTEGER :: i, n
  DOUBLE PRECISION :: alpha, mux, muy, tprev, tnext, cl, cr, s, c

  CALL load_mesh()
  n = nseg
  alpha = PAR(1)
  mux = U(n + 1)
  muy = U(n + 2)
  F(n + 1) = gap
  F(n + 2) = 0.0d0
  DO i = 1, n
    IF (i == 1) THEN
      tprev = alpha
    ELSE
      tprev = U(i - 1)
    END IF
    IF (i == n) THEN
      tnext = -alpha
    ELSE
      tnext = U(i + 1)
    END IF
    cl = (U(i) - tprev - pbar(i - 1)) / ell(i - 1)
    cr = (tnext - U(i) - pbar(i)) / ell(i)
    s = SIN(U(i))
    c = COS(U(i))
    F(i) = cl - cr + h(i) * (mux * s - muy * c)
    F(n + 1) = F(n + 1) - h(i) * c
    F(n + 2) = F(n + 2) - h(i) * s
  END DO
  IF (scaling == 1) F(1:n) = F(1:n) * h(1:n)
  IF (IJAC == 0) RETURN

  DFDU(:, :) = 0.0d0
  DO i = 1, n
    s = SIN(U(i))
    c = COS(U(i))
    DFDU(i, i) = 1.0d0 / ell(i - 1) + 1.0d0 / ell(i) + h(i) * (mux * c + muy * s)
    IF (i > 1) DFDU(i, i - 1) = -1.0d0 / ell(i - 1)
    IF (i < n) DFDU(i, i + 1) = -1.0d0 / ell(i)
    DFDU(i, n + 1) = h(i) * s
    DFDU(i, n + 2) = -h(i) * c
    DFDU(n + 1, i) = h(i) * s
    DFDU(n + 2, i) = -h(i) * c
  END DO
  IF (scaling == 1) THEN
    DO i = 1, n
      DFDU(i, :) = DFDU(i, :) * h(i)
    END DO
  END IF
  IF (IJAC == 1) RETURN

  DFDP(1:NDIM, 1) = 0.0d0
  DFDP(1, 1) = -1.0d0 / ell(0)
  DFDP(n, 1) = DFDP(n, 1) + 1.0d0 / ell(n)
  IF (scaling == 1) THEN
    DFDP(1, 1) = DFDP(1, 1) * h(1)
    DFDP(n, 1) = DFDP(n, 1) * h(n)
  END IF
END SUBROUTINE FUNC

SUBROUTINE STPNT(NDIM, U, PAR, T)
  USE strip_data
  IMPLICIT NONE
  INTEGER, INTENT(IN) :: NDIM
  DOUBLE PRECISION, INTENT(INOUT) :: U(NDIM), PAR(*)
  DOUBLE PRECISION, INTENT(IN) :: T
  INTEGER :: i, u_
  CALL load_mesh()
  IF (NDIM /= nseg + 2) STOP 'NDIM must be N + 2 (mesh.dat)'
  OPEN(NEWUNIT=u_, FILE='start.dat', STATUS='OLD', ACTION='READ')
  DO i = 1, NDIM
    READ(u_, *) U(i)
  END DO
  CLOSE(u_)
  PAR(1) = 0.0d0
  PAR(2) = 0.0d0
END SUBROUTINE STPNT

SUBROUTINE PVLS(NDIM, U, PAR)
  USE strip_data
  IMPLICIT NONE
  INTEGER, INTENT(IN) :: NDIM
  DOUBLE PRECISION, INTENT(IN) :: U(NDIM)
  DOUBLE PRECISION, INTENT(INOUT) :: PAR(*)
  INTEGER :: i
  PAR(2) = 0.0d0
  DO i = 1, nseg / 2
    PAR(2) = PAR(2) + h(i) * SIN(U(i))
  END DO
END SUBROUTINE PVLS

SUBROUTINE BCND
END SUBROUTINE BCND

SUBROUTINE ICND
END SUBROUTINE ICND

SUBROUTINE FOPT
END SUBROUTINE FOPT

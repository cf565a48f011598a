!----------------------------------------------------------------------------------------
! AUTO-07p equation file: the CONTINUOUS creased strip, a two-point boundary-value problem
! solved by AUTO's own orthogonal collocation (IPS = 4). Planar inextensible Kirchhoff
! elastica, B = L = 1, no gravity (docs/model.md):
!
!   x' = cos theta,   y' = sin theta,   theta' = k0(s) + m,   m' = mu_x sin theta - mu_y cos theta
!
! over s in [0, 1] (m = theta' - theta0' is the bending moment / B), the Euler-Lagrange
! equations of  1/2 int (theta' - theta0')^2 ds - mu_x (int cos theta - G) - mu_y int sin theta,
! i.e. jaxrod's Lagrangian in the limit N -> oo. Natural curvature of the crease (docs/model.md,
! jaxrod Strip.natural_angle):
!   theta0(s) = A tanh((s - 1/2)/s0),  A = (Psi0 - pi)/2,   k0 = theta0' = (A/s0) sech^2((s - 1/2)/s0).
! Clamps: x(0) = y(0) = 0, theta(0) = +alpha; x(1) = G, y(1) = 0, theta(1) = -alpha.
!
! Parameters: PAR(1) = alpha (symmetric clamp angle, rad), PAR(2) = mu_x, PAR(3) = mu_y
! (end force / B), PAR(4) = G (gap), PAR(5) = Psi0 (fold angle, rad), PAR(6) = s0 (fold width).
! Three of them are free in every run (NBC - NDIM + 1 = 3), e.g. (alpha, mu_x, mu_y).
!
! Two equivalent formulations, chosen by NDIM in the constants file:
!
! NDIM = 5, NBC = 7 ("plain"): U = (x, y, theta, m, s) at arclength s = t; s' = 1, s(0) = 0
!   carries the arclength the natural curvature depends on (AUTO's FUNC is autonomous).
!   BCs: x(0), y(0), theta(0) - alpha, s(0), x(1) - G, y(1), theta(1) + alpha.
!
! NDIM = 9, NBC = 11 ("folded"): the strip folded at the crease, t in [0, 1] running from both
!   clamps to the middle at once: U(1:4) = (x, y, theta, m) at s = t/2 (left half),
!   U(5:8) = (x, y, theta, m) at s = 1 - t/2 (right half, d/dt = -1/2 d/ds), U(9) = t.
!   BCs: the two clamps at t = 0 (7 conditions with t(0) = 0) and continuity of
!   (x, y, theta, m) at the crease, t = 1 (4 conditions).
!   The mirror symmetry of the strip (x -> G - x, theta -> -theta, mu_y -> -mu_y) becomes the
!   exchange of the two halves, which AUTO's collocation on one shared (adapted) mesh keeps
!   exactly: the pitchfork where an asymmetric mode goes unstable stays a true branch point
!   of the discretized problem. In the plain formulation the adapted mesh is not
!   mirror-symmetric, which unfolds that pitchfork (imperfect bifurcation) at finite NTST.
!
! Start (IRS = 0, STPNT): the straight strip with the gap closed, G = 1, Psi0 = pi (no crease),
! alpha = 0, mu = 0, an exact solution for every mu_x (the trivial branch of Euler buckling).
! Analytic derivatives (JAC = 1) in FUNC and BCND.
!----------------------------------------------------------------------------------------

SUBROUTINE CREASE(s, psi0, s0, k, dk_ds, dk_dpsi, dk_ds0)
  ! k0(s) and its derivatives with respect to s, Psi0 and s0
  IMPLICIT NONE
  DOUBLE PRECISION, INTENT(IN) :: s, psi0, s0
  DOUBLE PRECISION, INTENT(OUT) :: k, dk_ds, dk_dpsi, dk_ds0
  DOUBLE PRECISION :: amp, z, th, sech2
  amp = 0.5d0 * (psi0 - 4.0d0 * ATAN(1.0d0))
  z = (s - 0.5d0) / s0
  th = TANH(z)
  sech2 = 1.0d0 - th * th
  k = amp / s0 * sech2
  dk_ds = -2.0d0 * amp / (s0 * s0) * sech2 * th
  dk_dpsi = 0.5d0 / s0 * sech2
  dk_ds0 = amp / (s0 * s0) * sech2 * (2.0d0 * z * th - 1.0d0)
END SUBROUTINE CREASE

SUBROUTINE HALF(sg, U, PAR, k, F)
  ! right-hand side of one half, d/dt = sg * (1/2) d/ds (sg = +1 left half, -1 right half)
  IMPLICIT NONE
  DOUBLE PRECISION, INTENT(IN) :: sg, U(4), PAR(*), k
  DOUBLE PRECISION, INTENT(OUT) :: F(4)
  DOUBLE PRECISION :: h
  h = 0.5d0 * sg
  F(1) = h * COS(U(3))
  F(2) = h * SIN(U(3))
  F(3) = h * (k + U(4))
  F(4) = h * (PAR(2) * SIN(U(3)) - PAR(3) * COS(U(3)))
END SUBROUTINE HALF

SUBROUTINE FUNC(NDIM, U, ICP, PAR, IJAC, F, DFDU, DFDP)
  IMPLICIT NONE
  INTEGER, INTENT(IN) :: NDIM, ICP(*), IJAC
  DOUBLE PRECISION, INTENT(IN) :: U(NDIM), PAR(*)
  DOUBLE PRECISION, INTENT(OUT) :: F(NDIM)
  DOUBLE PRECISION, INTENT(INOUT) :: DFDU(NDIM, NDIM), DFDP(NDIM, *)
  DOUBLE PRECISION :: k, dks, dkp, dk0, c, sn, h, sg, s, dsdt
  INTEGER :: j, o, nh

  IF (NDIM == 5) THEN
    nh = 1            ! plain: one "half" = the whole strip, d/dt = d/ds
  ELSE IF (NDIM == 9) THEN
    nh = 2
  ELSE
    STOP 'elastica.f90: NDIM must be 5 (plain) or 9 (folded)'
  END IF
  IF (IJAC /= 0) DFDU(:, :) = 0.0d0
  IF (IJAC == 2) DFDP(1:NDIM, 1:6) = 0.0d0
  DO j = 1, nh
    o = 4 * (j - 1)
    IF (nh == 1) THEN
      sg = 2.0d0       ! h = sg/2 = 1
      s = U(NDIM)
      dsdt = 1.0d0
    ELSE IF (j == 1) THEN
      sg = 1.0d0
      s = 0.5d0 * U(NDIM)
      dsdt = 0.5d0
    ELSE
      sg = -1.0d0
      s = 1.0d0 - 0.5d0 * U(NDIM)
      dsdt = -0.5d0
    END IF
    h = 0.5d0 * sg
    CALL CREASE(s, PAR(5), PAR(6), k, dks, dkp, dk0)
    CALL HALF(sg, U(o + 1:o + 4), PAR, k, F(o + 1:o + 4))
    IF (IJAC == 0) CYCLE
    c = COS(U(o + 3))
    sn = SIN(U(o + 3))
    DFDU(o + 1, o + 3) = -h * sn
    DFDU(o + 2, o + 3) = h * c
    DFDU(o + 3, o + 4) = h
    DFDU(o + 3, NDIM) = h * dks * dsdt
    DFDU(o + 4, o + 3) = h * (PAR(2) * c + PAR(3) * sn)
    IF (IJAC == 1) CYCLE
    DFDP(o + 4, 2) = h * sn
    DFDP(o + 4, 3) = -h * c
    DFDP(o + 3, 5) = h * dkp
    DFDP(o + 3, 6) = h * dk0
  END DO
  F(NDIM) = 1.0d0
END SUBROUTINE FUNC

SUBROUTINE STPNT(NDIM, U, PAR, T)
  IMPLICIT NONE
  INTEGER, INTENT(IN) :: NDIM
  DOUBLE PRECISION, INTENT(INOUT) :: U(NDIM), PAR(*)
  DOUBLE PRECISION, INTENT(IN) :: T
  ! straight strip, gap closed (G = L = 1), no crease; s0 may be overridden with PAR={6: ...}
  PAR(1:3) = 0.0d0
  PAR(4) = 1.0d0
  PAR(5) = 4.0d0 * ATAN(1.0d0)
  PAR(6) = 0.02d0
  U(:) = 0.0d0
  IF (NDIM == 5) THEN
    U(1) = T
  ELSE
    U(1) = 0.5d0 * T
    U(5) = 1.0d0 - 0.5d0 * T
  END IF
  U(NDIM) = T
END SUBROUTINE STPNT

SUBROUTINE BCND(NDIM, PAR, ICP, NBC, U0, U1, FB, IJAC, DBC)
  IMPLICIT NONE
  INTEGER, INTENT(IN) :: NDIM, ICP(*), NBC, IJAC
  DOUBLE PRECISION, INTENT(IN) :: PAR(*), U0(NDIM), U1(NDIM)
  DOUBLE PRECISION, INTENT(OUT) :: FB(NBC)
  DOUBLE PRECISION, INTENT(INOUT) :: DBC(NBC, *)
  INTEGER :: i, ip

  ! columns of DBC: 1..NDIM d/dU0, NDIM+1..2 NDIM d/dU1, 2 NDIM + k d/dPAR(k)
  ip = 2 * NDIM
  IF (IJAC /= 0) DBC(1:NBC, 1:2 * NDIM + 6) = 0.0d0
  FB(1) = U0(1)
  FB(2) = U0(2)
  FB(3) = U0(3) - PAR(1)
  FB(4) = U0(NDIM)
  IF (NDIM == 5) THEN
    FB(5) = U1(1) - PAR(4)
    FB(6) = U1(2)
    FB(7) = U1(3) + PAR(1)
    IF (IJAC == 0) RETURN
    DBC(5, NDIM + 1) = 1.0d0
    DBC(6, NDIM + 2) = 1.0d0
    DBC(7, NDIM + 3) = 1.0d0
  ELSE
    FB(5) = U0(5) - PAR(4)
    FB(6) = U0(6)
    FB(7) = U0(7) + PAR(1)
    DO i = 1, 4
      FB(7 + i) = U1(i) - U1(4 + i)
    END DO
    IF (IJAC == 0) RETURN
    DBC(5, 5) = 1.0d0
    DBC(6, 6) = 1.0d0
    DBC(7, 7) = 1.0d0
    DO i = 1, 4
      DBC(7 + i, NDIM + i) = 1.0d0
      DBC(7 + i, NDIM + 4 + i) = -1.0d0
    END DO
  END IF
  DBC(1, 1) = 1.0d0
  DBC(2, 2) = 1.0d0
  DBC(3, 3) = 1.0d0
  DBC(4, NDIM) = 1.0d0
  DBC(3, ip + 1) = -1.0d0
  DBC(7, ip + 1) = 1.0d0
  DBC(5, ip + 4) = -1.0d0
END SUBROUTINE BCND

SUBROUTINE ICND
END SUBROUTINE ICND

SUBROUTINE FOPT
END SUBROUTINE FOPT

SUBROUTINE PVLS
END SUBROUTINE PVLS

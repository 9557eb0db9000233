"""Where each quantity lives in the filter's plain float64 arrays (named blocks, as KF-GINS'
``StateID``): a run can then stop at any IMU sample, be copied (a checkpoint) and resume
bit-identically, and the compiled kernels read the blocks as compile-time constants.

- ``x`` (NX): nominal state.
- ``P`` (NE, NE): covariance of the error state. Errors are ``true - estimate`` and the true
  attitude is ``(I + [phi x]) C_est``.
- ``aux`` (NA): the filter's bookkeeping between IMU samples.
- ``idx`` (NI): the next IMU / wheel / GNSS sample and output row.
- ``cfg`` (NC): constants of one run (:func:`estimator.filter.setup.kernel_config`).
- output rows (NO columns): what :func:`estimator.filter.kernel.write_row` records.

Quaternions are scalar-first (w, x, y, z), body FLU -> ENU, as everywhere in routefuse
(:mod:`estimator.nav.rotation`).
"""

from __future__ import annotations

# nominal state x
X_POS = 0  # (3) position ENU, m
X_VEL = 3  # (3) velocity ENU, m/s
X_QUAT = 6  # (4) attitude quaternion body->ENU, (w, x, y, z)
X_BG = 10  # (3) gyro bias, rad/s
X_BA = 13  # (3) accelerometer bias, m/s^2
X_SCALE = 16  # wheel-speed scale factor
X_GW = 17  # (3) GNSS wander ENU, m
X_GSF = 20  # the z gyro's scale-factor error s (measured = (1 + s) true + bias)
NX = 21

# error state (rows and columns of P)
E_ATT = 0  # (3) attitude: a rotation of the ENU frame, rad
E_VEL = 3  # (3)
E_POS = 6  # (3)
E_BG = 9  # (3)
E_BA = 12  # (3)
E_SCALE = 15
E_GW = 16  # (3)
# considered states (Schmidt: never corrected, their gain is zero) come last, from E_LANE on
E_LANE = 19  # the lane-offset error the route pseudo-positions keep
E_MAP = 20  # (2) the map-bias error E, N the route pseudo-positions keep (extensions.map_bias)
E_ROT = 22  # the map's rotation error (rad), considered but where extensions.map_turn_estimate
E_GSF = 23  # the z gyro's scale-factor error: considered (extensions.gyro_scale_consider) or
# estimated (extensions.gyro_scale_state, C_GSF_EST)
NE = 24

# aux: bookkeeping
A_TIME = 0  # time of the state: the last IMU sample processed
A_COV_T = 1  # time accumulated since the last covariance propagation
A_COV_C = 2  # (9) integral of C_bn dt over it
A_COV_F = 11  # (3) integral of C_bn f dt over it
A_DR = 14  # (2) DR track: E, N integrated from the mechanised velocity only
A_DIST = 16  # horizontal distance travelled, m
A_NEXT_OUT = 17  # time of the next regular output row
A_GNSS_USED = 18  # a fix was accepted since the last output row
A_LAST_AID = 19  # time of the last wheel / NHC / ZUPT update
A_PREV_GYRO = 20  # (3) previous IMU sample (for the mid-point integration)
A_PREV_ACCEL = 23  # (3)
A_REJECT_SINCE = 26  # time of the first of the current run of rejected fixes, or -1
A_INFLATE = 27  # 1: widen the position covariance so the next fix is accepted (after pseudo-obs)
A_GYRO_SUM = 28  # (3) gyro sum over the stationary stretch since the last ZUPT
A_GYRO_N = 31  # number of samples in that sum
A_TRUST_T = 32  # time of the last trusted fix
A_CHAIN_T0 = 33  # start of the current run of mutually consistent fixes
A_CHAIN_T = 34  # the run's last fix: time
A_CHAIN_POS = 35  # (2) its E, N
A_CHAIN_DR = 37  # (2) the DR track at it
A_USED_DIST = 39  # A_DIST at the last fix used
A_ROUTE = 40  # (3) lane-offset and map-bias (E, N) errors estimated since the outage start
A_ROUTE_EST = 43  # 1: this outage's route pseudo-positions estimate them
A_MAP_AT = 44  # (2) E, N where E_MAP is the map-bias error (E_ROT turns it elsewhere)
A_ROT_EST = 46  # 1: this outage's route pseudo-positions estimate the map's rotation error
A_ROT = 47  # the map's rotation error estimated since the outage start, rad
A_ROT_SHIFT = 48  # (2) with it, the map's shift at the origin: sum of -dr J a (a = A_MAP_AT)
A_COV_W = 50  # (3) integral of C_bn e_z w_z dt (body z rate) over the pending propagation
A_POS_WALK = 53  # (m^2/s) a random walk of the horizontal position in an outage: the drift the
# exit check found beyond the model in earlier ones (extensions.exit_adapt), 0 at the next fix used
# stamped after A_WALK_FROM
A_EXIT_WALK = 54  # what A_POS_WALK is set to at an outage's start: the exits so far, summed
A_WALK_FROM = 55  # the outage's start, its last fix: that fix, pending when it is set, keeps it
NA = 56

# idx
I_IMU, I_WHEEL, I_GNSS, I_OUT, NI = 0, 1, 2, 3, 4

# cfg: constants of one run
C_COV_DT = 0  # covariance propagation interval, s
C_ARW2 = 1  # gyro white noise PSD, rad^2/s
C_VRW2 = 2  # accel white noise PSD, (m/s)^2/s
C_TAU_G = 3  # gyro bias correlation time, s
C_QBG = 4  # gyro bias GM driving PSD 2 sigma^2 / tau
C_TAU_A = 5  # accelerometer bias correlation time, s
C_QBA = 6  # accelerometer bias GM driving PSD
C_WHEEL_VAR = 7
C_NHC_VAR = 8
C_ZUPT_VAR = 9
C_GNSS_GATE = 10  # chi-square gate of a fix
C_LEVER = 11  # (3) antenna in body FLU
C_GRAVITY = 14
C_WIE = 15  # (3) Earth rate in ENU
C_OUT_DT = 18
C_AID_DT = 19
C_SCALE_ON = 20  # 1: the wheel scale is estimated
C_RESET_S = 21
C_WHEEL_GAP = 22  # wheel samples further apart than this are not interpolated
C_TAU_W = 23  # GNSS wander correlation time
C_QW_H = 24  # GNSS wander driving PSD, horizontal
C_QW_V = 25
C_ROBUST = 26  # test fixes against the dead-reckoned motion
C_WHITE_VAR = 27  # typical white variance of a horizontal fix coordinate
C_CROSS_WIDEN = 28  # 1: a fix's heading widening takes only its innovation across the travel
C_GSF_EST = 29  # 1: the z gyro's scale factor is estimated (E_GSF gets a gain, X_GSF applied)
C_GSF_BLIND = 30  # 1: no gain uses the considered scale factor (extensions.gyro_scale_blind_gain)
C_NHC_TILT2 = 31  # (rad^2) the IMU's misalignment with the vehicle's axes: NHC variance per (m/s)^2
NC = 32

# output rows
O_T = 0
O_POS = 1  # (3)
O_VEL = 4  # (3)
O_RPY = 7  # (3) roll, pitch, yaw
O_SIG_POS = 10  # (3)
O_SIG_YAW = 13
O_GNSS = 14  # a fix was used since the previous row
O_DR = 15  # (2) the DR track
O_DIST = 17  # distance travelled
O_COV_EN = 18  # the E and N position errors' covariance
NO = 19

# what run_until returns
STATUS_DONE = 0
STATUS_FULL = 1  # the output buffer has no room: grow it and call again
STATUS_DIVERGED = 2

"""What the estimator fuses and how much it trusts each source: parameters named as PX4's
EKF2 names them, and the sensor sets `--sensors` chooses among."""

from __future__ import annotations

from dataclasses import dataclass

from simbridge.config import param

HEIGHT_BARO, HEIGHT_GPS, HEIGHT_RANGE, HEIGHT_VISION = 0, 1, 2, 3
HEIGHT_NAMES = {0: "baro", 1: "gps", 2: "range", 3: "vision"}
EV_HPOS, EV_VPOS, EV_YAW = 1, 2, 8
GPS_POS, GPS_ALT, GPS_VEL = 1, 2, 4
SENSOR_SETS = {  # `--sensors NAME`: the parameters of each sensor set
    "mocap": {"EKF2_EV_CTRL": 11, "EKF2_GPS_CTRL": 0, "EKF2_OF_CTRL": 1, "EKF2_HGT_REF": 3},
    "flow": {"EKF2_EV_CTRL": 0, "EKF2_GPS_CTRL": 0, "EKF2_OF_CTRL": 1, "EKF2_HGT_REF": 2},
    "gps": {"EKF2_EV_CTRL": 0, "EKF2_GPS_CTRL": 7, "EKF2_OF_CTRL": 0, "EKF2_HGT_REF": 0},
}


@dataclass(frozen=True)
class EstimatorParams:
    ev_ctrl: int = param(
        11, lo=0, hi=15, doc="motion capture: 1 horizontal position, 2 vertical, 8 yaw"
    )
    gps_ctrl: int = param(0, lo=0, hi=7, doc="GPS: 1 lat/lon, 2 altitude, 4 velocity")
    of_ctrl: int = param(
        1,
        lo=0,
        hi=1,
        doc="optical flow: 1 fused while the range is valid and no motion capture position "
        "comes (a fallback: beside 1 mm poses at 100 Hz it adds nothing but cost)",
    )
    rng_ctrl: int = param(
        1,
        lo=0,
        hi=2,
        doc="range: 1 conditional (terrain; the height while low and slow over a baro or "
        "GPS reference, PX4's range aid), 2 terrain, and the height when it is the reference",
    )
    rng_aid_max_height_m: float = param(
        0.5, unit="m", lo=0.0, hi=10.0, doc="range aid below this height (hysteresis 20 %)"
    )
    rng_aid_max_speed_m_s: float = param(
        1.0, unit="m/s", lo=0.0, hi=10.0, doc="range aid below this horizontal speed"
    )
    baro_ctrl: int = param(1, lo=0, hi=1, doc="barometer: 1 height when it is the reference")
    hgt_ref: int = param(3, lo=0, hi=3, doc="height reference: 0 baro, 1 GPS, 2 range, 3 vision")
    mag_decl_deg: float = param(
        5.5, unit="deg", lo=-180.0, hi=180.0, doc="magnetic declination (packaged worlds: 5.5)"
    )
    ev_pos_noise_m: float = param(0.002, unit="m", lo=1e-4, hi=10.0, doc="mocap position sd")
    ev_att_noise_rad: float = param(0.005, unit="rad", lo=1e-4, hi=1.0, doc="mocap yaw sd")
    rng_noise_m: float = param(0.003, unit="m", lo=1e-4, hi=1.0, doc="range sd at short range")
    rng_noise_per_m: float = param(0.01, lo=0.0, hi=1.0, doc="range sd added per metre")
    of_noise_rad_s: float = param(0.15, unit="rad/s", lo=1e-3, hi=10.0, doc="flow rate sd")
    gps_pos_noise_m: float = param(0.5, unit="m", lo=0.01, hi=100.0, doc="GPS position sd")
    gps_vel_noise_m_s: float = param(0.15, unit="m/s", lo=0.01, hi=10.0, doc="GPS velocity sd")
    baro_noise_m: float = param(0.15, unit="m", lo=0.01, hi=100.0, doc="barometer height sd")
    mag_noise_rad: float = param(0.05, unit="rad", lo=1e-3, hi=3.0, doc="heading sd")
    gate_sd: float = param(5.0, lo=1.0, hi=100.0, doc="innovation gate, standard deviations")
    source_timeout_s: float = param(
        0.3, unit="s", lo=0.01, hi=10.0, doc="a source silent this long is lost"
    )
    ev_reset_s: float = param(
        0.5, unit="s", lo=0.01, hi=10.0,
        doc="motion capture arriving but rejected this long: the position reset to it",
    )  # fmt: skip

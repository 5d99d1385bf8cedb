// Generated from the wire models (skyhelm_wire) by `python -m tools.gen_wire_js`;
// do not edit. tests/test_wire_js.py fails when it is not current.

/**
 * A NED acceleration.
 * @typedef {Object} AccelerationNedBody
 * @property {"acceleration_ned"} type
 * @property {number} north_m_s2 (m/s^2)
 * @property {number} east_m_s2 (m/s^2)
 * @property {number} down_m_s2 (m/s^2)
 * @property {number|null} [yaw_deg]
 */

/**
 * One check PX4 reports failing or warning about, in its words.
 * @typedef {Object} ArmingCheckOut
 * @property {string} text PX4's words
 * @property {string} severity PX4's log level; ERROR keeps the modes it concerns from arming
 * @property {Array<string>} modes the modes it concerns (empty: not told)
 * @property {string|null} component PX4's health component it belongs to
 * @property {"arming_check"|"health"} kind
 */

/**
 * Ready to arm in the mode flown, and why not.
 * @typedef {Object} ArmingChecksOut
 * @property {boolean|null} ready arming would pass PX4's checks in `mode` (null: not told yet)
 * @property {string} mode the mode judged: the one the vehicle flies
 * @property {"events"|"sys_status"} source events: PX4's arming-check report; sys_status: only SYS_STATUS's pre-arm and sensor health bits (no events metadata)
 * @property {Array<string>} can_arm_modes the modes PX4 would arm in now
 * @property {Array<ArmingCheckOut>} reasons the failing checks (and warnings) that concern `mode`, errors first
 * @property {Array<ArmingCheckOut>} other_reasons the checks that concern only other modes
 * @property {"ready"|"arm_switches_mode"|"not_ready"|null} [verdict] ready: arm, takeoff and an offboard start would be taken; arm_switches_mode: PX4 refuses `mode` for its own checks only and SkyHelm's arm switches to `arm_switches_to` first, where PX4 would arm; not_ready: see `reasons` and `waiting_for` (null: not told yet)
 * @property {string|null} [arm_switches_to] the mode SkyHelm's arm switches to before arming (null: arms in `mode`)
 * @property {Array<string>} [waiting_for] what a takeoff or an offboard start still needs (home position, position estimate)
 */

/**
 * Roll, pitch and yaw with a normalised thrust.
 * @typedef {Object} AttitudeBody
 * @property {"attitude"} type
 * @property {number} roll_deg (deg)
 * @property {number} pitch_deg (deg)
 * @property {number} yaw_deg (deg)
 * @property {number} thrust (1)
 */

/**
 * @typedef {Object} AttitudeOut
 * @property {number|null} roll_deg
 * @property {number|null} pitch_deg
 * @property {number|null} yaw_deg
 * @property {number|null} rollspeed_deg_s
 * @property {number|null} pitchspeed_deg_s
 * @property {number|null} yawspeed_deg_s
 */

/**
 * @typedef {Object} BatteryOut
 * @property {number|null} voltage_v
 * @property {number|null} current_a
 * @property {number|null} remaining_pct
 * @property {number|null} [consumed_mah] BATTERY_STATUS.current_consumed
 * @property {number|null} [time_remaining_s] the vehicle's own estimate (BATTERY_STATUS.time_remaining)
 */

/**
 * Body angular rates with a normalised thrust.
 * @typedef {Object} BodyRatesBody
 * @property {"body_rates"} type
 * @property {number} roll_rate_deg_s (deg/s)
 * @property {number} pitch_rate_deg_s (deg/s)
 * @property {number} yaw_rate_deg_s (deg/s)
 * @property {number} thrust (1)
 */

/**
 * A process the server runs and supervises.
 * @typedef {Object} ChildProcessOut
 * @property {string} name 'setpoint sender', 'foxglove worker' or 'simulated vehicle'
 * @property {boolean} running
 * @property {number|null} [pid]
 * @property {number} [restarts] started again after a fault
 * @property {number} [faults] deaths and stops seen (kill, crash, no answer)
 * @property {string|null} [last_fault] the last fault and its cause
 * @property {boolean} [gave_up] not started again: it failed too often
 */

/**
 * @typedef {Object} CommandResultOut
 * @property {string} command
 * @property {"ACCEPTED"|"TEMPORARILY_REJECTED"|"DENIED"|"UNSUPPORTED"|"FAILED"|"IN_PROGRESS"|"CANCELLED"|"TIMEOUT"|"LINK_LOST"|"NOT_CONFIRMED"} result
 * @property {number|null} result_code MAV_RESULT as received
 * @property {number} elapsed_ms
 * @property {string|null} [reason] the vehicle's STATUSTEXT explaining a refusal
 */

/**
 * A refusal not tied to one request (the lease, the message rate).
 * @typedef {Object} ControlErrorMessage
 * @property {"error"} type
 * @property {string} reason
 * @property {string|null} [field]
 * @property {number|null} [limit]
 * @property {string|null} [holder]
 * @property {number|null} [retry_after_s]
 */

/**
 * GET /control: who holds it, since when, and a pending takeover request; all null
 * while nobody holds it.
 * @typedef {Object} ControlStatusOut
 * @property {string|null} [holder] "<token name> · <client label>"
 * @property {"rest"|"ws"|null} [session]
 * @property {number|null} [since_s] how long the holder has held it
 * @property {number|null} [expires_in_s] left of the TTL without a renewal
 * @property {number|null} [ttl_s]
 * @property {TakeoverRequestOut|null} [request] a pending takeover request
 * @property {number|null} [holder_pid] the holder's process, watched: the lease ends when it exits
 * @property {LeaseEndOut|null} [last_end] how the vehicle's last lease ended; null when none has
 */

/**
 * @typedef {Object} ErrorDetail
 * @property {string} reason
 * @property {string|null} [field]
 * @property {number|null} [limit]
 * @property {string|null} [holder]
 * @property {number|null} [retry_after_s] 429: when to try again (Retry-After)
 */

/**
 * @typedef {Object} ErrorOut
 * @property {ErrorDetail} detail
 */

/**
 * ESTIMATOR_STATUS: the flags set and the test ratios PX4 checks its innovations
 * against (1.0 is the limit).
 * @typedef {Object} EstimatorOut
 * @property {Array<string>} flags ESTIMATOR_STATUS flags set, without ESTIMATOR_
 * @property {boolean} healthy attitude, horizontal velocity and position valid
 * @property {number|null} pos_horiz_ratio
 * @property {number|null} pos_vert_ratio
 * @property {number|null} mag_ratio
 */

/**
 * Something that happened to the vehicle or its control (``kind`` says what; ``data``
 * depends on the kind: docs/api.md lists them).
 * @typedef {Object} EventMessage
 * @property {"event"} type
 * @property {number} vehicle
 * @property {string} kind
 * @property {number} time_s
 * @property {Object} data
 */

/**
 * @typedef {Object} GlobalOut
 * @property {number|null} lat_deg
 * @property {number|null} lon_deg
 * @property {number|null} alt_amsl_m
 * @property {number|null} alt_rel_m
 */

/**
 * @typedef {Object} GpsOut
 * @property {string} fix_type
 * @property {number} satellites
 * @property {number|null} hdop
 */

/**
 * @typedef {Object} HealthOut
 * @property {"ok"} status
 * @property {string} version
 * @property {number} vehicles
 * @property {boolean} [read_only] a replayed recording: control calls answer 403
 * @property {Array<ChildProcessOut>} [processes] the processes the server runs, as supervised
 */

/**
 * @typedef {Object} HomeOut
 * @property {number|null} lat_deg
 * @property {number|null} lon_deg
 * @property {number|null} alt_amsl_m
 * @property {number|null} north_m
 * @property {number|null} east_m
 * @property {number|null} down_m
 */

/**
 * @typedef {Object} LeaseEndOut
 * @property {string} holder
 * @property {"released"|"closed"|"expired"|"taken_over"|"gone"} end gone: the holder's process exited
 * @property {number} ago_s
 * @property {number|null} [holder_pid]
 */

/**
 * The control socket's lease ended; the socket closes after this message.
 * @typedef {Object} LeaseEndedMessage
 * @property {"lease"} type
 * @property {"released"|"closed"|"expired"|"taken_over"|"gone"|"ended"} state
 * @property {string|null} [by] taken_over: who took it
 */

/**
 * The control socket's lease, once granted.
 * @typedef {Object} LeaseMessage
 * @property {string} lease_id
 * @property {string} holder
 * @property {"rest"|"ws"} session
 * @property {number} ttl_s
 * @property {number} expires_in_s
 * @property {number} since_s how long this lease has been held
 * @property {PositionNedBody|VelocityNedBody|VelocityBodyBody|AccelerationNedBody|PositionVelocityNedBody|PositionGlobalBody|AttitudeBody|BodyRatesBody|OffsetNedBody|OffsetBodyBody|RawLocalBody|null} [setpoint] the setpoint being streamed now (start from it); null when none
 * @property {string|null} [taken_from] the holder this lease took control from
 * @property {"lease"} type
 */

/**
 * @typedef {Object} LeaseOut
 * @property {string} lease_id
 * @property {string} holder
 * @property {"rest"|"ws"} session
 * @property {number} ttl_s
 * @property {number} expires_in_s
 * @property {number} since_s how long this lease has been held
 * @property {PositionNedBody|VelocityNedBody|VelocityBodyBody|AccelerationNedBody|PositionVelocityNedBody|PositionGlobalBody|AttitudeBody|BodyRatesBody|OffsetNedBody|OffsetBodyBody|RawLocalBody|null} [setpoint] the setpoint being streamed now (start from it); null when none
 * @property {string|null} [taken_from] the holder this lease took control from
 */

/**
 * The lease as the vehicle's state shows it.
 * @typedef {Object} LeaseStatusOut
 * @property {string|null} holder
 * @property {number|null} expires_in_s
 */

/**
 * A link's traffic: what came in, what went out, what was lost or broken.
 * @typedef {Object} LinkOut
 * @property {string} url
 * @property {boolean} connected at least one vehicle on the link is heard (not silent)
 * @property {number} frames_in
 * @property {number} frames_out
 * @property {number} bytes_in
 * @property {number} bytes_out
 * @property {number} lost_frames sequence gaps, per source system and component
 * @property {number} bad_frames bad CRC, garbage, truncated frames: counted and dropped
 * @property {number|null} last_heartbeat_age_s null before the first vehicle HEARTBEAT
 * @property {number} reconnects
 * @property {SigningOut|null} [signing]
 * @property {number} [unverified_frames] frames whose message id cannot be CRC-checked: counted and dropped
 */

/**
 * How well one vehicle is heard: the figures behind the lost verdict and the warning.
 * @typedef {Object} LinkQualityOut
 * @property {number} silent_s since the vehicle's last valid frame
 * @property {number} lost_after_s the silence that makes it lost: silence_timeout_s while it streams, heartbeat_timeout_s otherwise
 * @property {number} rate_hz valid frames a second from the vehicle
 * @property {number|null} loss_in_pct vehicle -> server frames lost over the last 5 s (sequence numbers)
 * @property {number|null} loss_out_pct server -> vehicle frames lost over the last 5 s, as the vehicle reports it (PX4's LINK_NODE_STATUS); null where it does not
 * @property {number} heartbeat_age_s
 * @property {boolean} degraded a warning before the verdict: see warnings
 * @property {Array<"silence"|"loss_in"|"loss_out"|"heartbeat">} causes
 * @property {Array<string>} warnings
 */

/**
 * @typedef {Object} LinkSigningOut
 * @property {string} url
 * @property {Array<number>} vehicles
 * @property {SigningOut} signing
 */

/**
 * A position relative to where the vehicle is and where it points; sent as a
 * position_ned.
 * @typedef {Object} OffsetBodyBody
 * @property {"offset_body"} type
 * @property {number} forward_m (m)
 * @property {number} right_m (m)
 * @property {number} down_m (m)
 * @property {number|null} [yaw_deg]
 */

/**
 * A position relative to where the vehicle is, in NED; sent as a position_ned.
 * @typedef {Object} OffsetNedBody
 * @property {"offset_ned"} type
 * @property {number} north_m (m)
 * @property {number} east_m (m)
 * @property {number} down_m (m)
 * @property {number|null} [yaw_deg]
 */

/**
 * @typedef {Object} OriginOut
 * @property {number|null} lat_deg
 * @property {number|null} lon_deg
 * @property {number|null} alt_amsl_m
 */

/**
 * A named value (``values``: the value) or a bit of a bitmask (``bitmask``: its index).
 * @typedef {Object} ParamChoiceOut
 * @property {number} value
 * @property {string} description
 */

/**
 * One parameter as the vehicle's metadata describes it; empty or null where it says
 * nothing. ``min``, ``max``, ``default`` and ``increment`` are in ``units``.
 * @typedef {Object} ParamInfoOut
 * @property {string} name
 * @property {string} type PX4's type name: Float or Int32
 * @property {string} group e.g. "Multicopter Position Control"
 * @property {string} category Standard or Developer
 * @property {string} short_desc
 * @property {string} long_desc
 * @property {string} units e.g. "m/s"; empty for none
 * @property {number|null} min
 * @property {number|null} max
 * @property {number|null} default the firmware's default
 * @property {number|null} decimal_places
 * @property {number|null} increment
 * @property {boolean} reboot_required a new value takes effect after a reboot
 * @property {Array<ParamChoiceOut>} values named values, for an enumeration
 * @property {Array<ParamChoiceOut>} bitmask named bits (value = bit index)
 */

/**
 * Every parameter the vehicle's metadata describes, by name. A vehicle that serves no
 * metadata answers ``available`` false with the reason in ``error``.
 * @typedef {Object} ParamMetadataOut
 * @property {boolean} available
 * @property {string|null} [error]
 * @property {Object<string, ParamInfoOut>} parameters
 */

/**
 * @typedef {Object} ParamOut
 * @property {string} name
 * @property {number|null} value the value the vehicle echoed
 */

/**
 * @typedef {Object} ParamsOut
 * @property {Object<string, number|null>} params
 */

/**
 * A global position; the altitude is AMSL, above home or above terrain.
 * @typedef {Object} PositionGlobalBody
 * @property {"position_global"} type
 * @property {number} lat_deg (deg)
 * @property {number} lon_deg (deg)
 * @property {number} alt_m (m)
 * @property {"amsl"|"relative"|"terrain"} [alt_frame]
 * @property {number|null} [yaw_deg]
 */

/**
 * A local NED position; without a yaw it keeps the current heading.
 * @typedef {Object} PositionNedBody
 * @property {"position_ned"} type
 * @property {number} north_m (m)
 * @property {number} east_m (m)
 * @property {number} down_m (m)
 * @property {number|null} [yaw_deg]
 */

/**
 * @typedef {Object} PositionNedOut
 * @property {number|null} north_m
 * @property {number|null} east_m
 * @property {number|null} down_m
 */

/**
 * A local NED position with the velocity (and optionally acceleration) to fly it at.
 * @typedef {Object} PositionVelocityNedBody
 * @property {"position_velocity_ned"} type
 * @property {number} north_m (m)
 * @property {number} east_m (m)
 * @property {number} down_m (m)
 * @property {number} north_m_s (m/s)
 * @property {number} east_m_s (m/s)
 * @property {number} down_m_s (m/s)
 * @property {number|null} [north_m_s2]
 * @property {number|null} [east_m_s2]
 * @property {number|null} [down_m_s2]
 * @property {number|null} [yaw_deg]
 */

/**
 * SET_POSITION_TARGET_LOCAL_NED as PX4 reads it: MAV_FRAME number,
 * POSITION_TARGET_TYPEMASK bits, SI units (yaw in rad, yaw_rate in rad/s).
 * @typedef {Object} RawLocalBody
 * @property {"raw_local"} type
 * @property {number} frame
 * @property {number} type_mask
 * @property {number} [x] (m)
 * @property {number} [y] (m)
 * @property {number} [z] (m)
 * @property {number} [vx] (m/s)
 * @property {number} [vy] (m/s)
 * @property {number} [vz] (m/s)
 * @property {number} [afx] (m/s^2)
 * @property {number} [afy] (m/s^2)
 * @property {number} [afz] (m/s^2)
 * @property {number} [yaw] (rad)
 * @property {number} [yaw_rate] (rad/s)
 */

/**
 * The answer to one control request: the REST status and body it would have had.
 * @typedef {Object} ResultMessage
 * @property {"result"} type
 * @property {*} id the request's id, as sent
 * @property {string} request the request's type
 * @property {number} status
 * @property {boolean} ok
 * @property {*} body
 */

/**
 * Where a click in the 3D scene met the ground: ENU metres around the first vehicle's
 * local origin, and lat/lon once that origin is known.
 * @typedef {Object} SceneClickMessage
 * @property {"scene_click"} type
 * @property {number} seq
 * @property {number} time_s
 * @property {number} east_m
 * @property {number} north_m
 * @property {number} up_m
 * @property {number|null} lat_deg
 * @property {number|null} lon_deg
 * @property {number|null} alt_amsl_m
 */

/**
 * @typedef {Object} SentSetpointOut
 * @property {PositionNedBody|VelocityNedBody|VelocityBodyBody|AccelerationNedBody|PositionVelocityNedBody|PositionGlobalBody|AttitudeBody|BodyRatesBody|OffsetNedBody|OffsetBodyBody|RawLocalBody} setpoint as sent: the request's shape, offsets resolved
 * @property {string} message
 * @property {number} frame
 * @property {number} type_mask
 */

/**
 * One link's signing (also inside every vehicle state's `link`).
 * @typedef {Object} SigningOut
 * @property {boolean} enabled the link signs what it sends and checks what it gets
 * @property {boolean} vehicles_signed every vehicle on the link answered with frames verified by our key within the last 3 s: the link is signed both ways
 * @property {number} signed_in frames accepted with a good signature
 * @property {number} unsigned_in unsigned frames accepted (allowlist, or signing off)
 * @property {number} rejected frames rejected: the three counters below together
 * @property {number} rejected_bad_signature
 * @property {number} rejected_replay
 * @property {number} rejected_unsigned
 * @property {number} provisions keys set, rotated or removed since the server started
 */

/**
 * @typedef {Object} SigningStatusOut
 * @property {boolean} enabled the server holds a signing key
 * @property {boolean} key_file_set signing_key_file is configured: keys can be set
 * @property {Array<LinkSigningOut>} links
 */

/**
 * A state snapshot: the REST state, with the vehicle's type as ``vehicle_type``.
 * @typedef {Object} StateMessage
 * @property {number} id
 * @property {number} sysid
 * @property {number} compid
 * @property {"state"} type
 * @property {string} autopilot
 * @property {boolean} connected
 * @property {number|null} last_heartbeat_age_s
 * @property {string} mode
 * @property {string|null} user_mode
 * @property {boolean} armed
 * @property {boolean|null} ready_to_arm PX4's pre-arm bit: arming would pass its checks in the current mode
 * @property {string} system_status
 * @property {"UNDEFINED"|"ON_GROUND"|"IN_AIR"|"TAKEOFF"|"LANDING"} landed_state
 * @property {"UNDEFINED"|"MC"|"FW"|"TRANSITION_TO_FW"|"TRANSITION_TO_MC"} vtol_state
 * @property {PositionNedOut|null} position_ned metres north, east and down of the estimator's local origin (PX4's EKF origin, the state's `origin`: set where the estimator first had a position, normally where the vehicle was switched on, or by POST /origin), not of home or of where a flight started: a script that flies a leg reads it at the start and compares with that
 * @property {VelocityNedOut|null} velocity_ned
 * @property {GlobalOut|null} global
 * @property {AttitudeOut|null} attitude
 * @property {number|null} ground_speed_m_s
 * @property {number|null} air_speed_m_s
 * @property {number|null} climb_rate_m_s
 * @property {number|null} heading_deg
 * @property {BatteryOut|null} battery
 * @property {GpsOut|null} gps
 * @property {HomeOut|null} home
 * @property {OriginOut|null} origin
 * @property {PositionNedBody|VelocityNedBody|VelocityBodyBody|AccelerationNedBody|PositionVelocityNedBody|PositionGlobalBody|AttitudeBody|BodyRatesBody|OffsetNedBody|OffsetBodyBody|RawLocalBody|null} setpoint the streamed setpoint, offsets resolved
 * @property {PositionNedOut|null} target_ned
 * @property {StreamOut} stream
 * @property {LeaseStatusOut} lease
 * @property {Array<number|null>} actuator_outputs
 * @property {Array<StatusTextOut>} statustext
 * @property {string|null} rtl_phase
 * @property {LinkOut} link
 * @property {number} updated_s time.monotonic() of the newest telemetry
 * @property {Array<string>} [stale] fields not current: all while the link is lost, those not reported again since it came back (mode reads UNKNOWN until it is)
 * @property {EstimatorOut|null} [estimator]
 * @property {Array<string>|null} [sensors_unhealthy] SYS_STATUS sensors present and enabled but not healthy
 * @property {Object<string, number>} [message_ages_s] seconds since each source message (by MAVLink name) was last received
 * @property {LinkQualityOut|null} [link_quality]
 * @property {string|null} [lost_reason] how the server noticed the vehicle's loss, while `connected` is false ("nothing heard for 1.0 s", "simulated vehicle's process ended (killed by SIGKILL)"); null while it is connected
 * @property {ArmingChecksOut|null} [arming_checks] ready to fly: PX4's arming checks for the mode flown, and why not
 * @property {number} vehicle
 * @property {string} vehicle_type
 * @property {Array<string>} [telemetry_refused] telemetry streams the vehicle refused to send
 */

/**
 * A STATUSTEXT the vehicle sent, its chunks joined.
 * @typedef {Object} StatusTextMessage
 * @property {"statustext"} type
 * @property {number} vehicle
 * @property {number} time_s
 * @property {string} severity
 * @property {string} text
 */

/**
 * @typedef {Object} StatusTextOut
 * @property {number} time_s
 * @property {string} severity
 * @property {string} text
 */

/**
 * Setpoint stream figures since it started; intervals from a bounded recent window.
 * @typedef {Object} StreamOut
 * @property {boolean} [active]
 * @property {number|null} [rate_hz]
 * @property {number|null} [interval_p50_ms]
 * @property {number|null} [interval_p99_ms]
 * @property {number|null} [max_gap_ms]
 * @property {number} [gaps]
 * @property {number} [sent]
 * @property {number|null} [since_last_ms]
 * @property {string} [sender] who sends the stream's frames now: 'process' (the setpoint sender process), 'thread' (the server's sender thread: no process, or it failed), 'loop' or 'none' (stopped)
 * @property {number} [sender_restarts] setpoint sender processes started after a fault
 * @property {string|null} [sender_fault] the sender process's last fault and its cause (null: none)
 */

/**
 * @typedef {Object} TakeoverAnswerOut
 * @property {string} request_id
 * @property {boolean} grant
 * @property {string} by
 */

/**
 * @typedef {Object} TakeoverRequestOut
 * @property {string} request_id
 * @property {string} by
 * @property {number} timeout_s
 * @property {number} expires_in_s
 */

/**
 * Someone asks the holder for control; answer with ``takeover_answer``.
 * @typedef {Object} TakeoverRequestedMessage
 * @property {"takeover_requested"} type
 * @property {string} request_id
 * @property {string} by
 * @property {number} timeout_s
 */

/**
 * A vehicle's state: one snapshot of everything the link knows of it.
 * @typedef {Object} VehicleStateOut
 * @property {number} id
 * @property {number} sysid
 * @property {number} compid
 * @property {string} type
 * @property {string} autopilot
 * @property {boolean} connected
 * @property {number|null} last_heartbeat_age_s
 * @property {string} mode
 * @property {string|null} user_mode
 * @property {boolean} armed
 * @property {boolean|null} ready_to_arm PX4's pre-arm bit: arming would pass its checks in the current mode
 * @property {string} system_status
 * @property {"UNDEFINED"|"ON_GROUND"|"IN_AIR"|"TAKEOFF"|"LANDING"} landed_state
 * @property {"UNDEFINED"|"MC"|"FW"|"TRANSITION_TO_FW"|"TRANSITION_TO_MC"} vtol_state
 * @property {PositionNedOut|null} position_ned metres north, east and down of the estimator's local origin (PX4's EKF origin, the state's `origin`: set where the estimator first had a position, normally where the vehicle was switched on, or by POST /origin), not of home or of where a flight started: a script that flies a leg reads it at the start and compares with that
 * @property {VelocityNedOut|null} velocity_ned
 * @property {GlobalOut|null} global
 * @property {AttitudeOut|null} attitude
 * @property {number|null} ground_speed_m_s
 * @property {number|null} air_speed_m_s
 * @property {number|null} climb_rate_m_s
 * @property {number|null} heading_deg
 * @property {BatteryOut|null} battery
 * @property {GpsOut|null} gps
 * @property {HomeOut|null} home
 * @property {OriginOut|null} origin
 * @property {PositionNedBody|VelocityNedBody|VelocityBodyBody|AccelerationNedBody|PositionVelocityNedBody|PositionGlobalBody|AttitudeBody|BodyRatesBody|OffsetNedBody|OffsetBodyBody|RawLocalBody|null} setpoint the streamed setpoint, offsets resolved
 * @property {PositionNedOut|null} target_ned
 * @property {StreamOut} stream
 * @property {LeaseStatusOut} lease
 * @property {Array<number|null>} actuator_outputs
 * @property {Array<StatusTextOut>} statustext
 * @property {string|null} rtl_phase
 * @property {LinkOut} link
 * @property {number} updated_s time.monotonic() of the newest telemetry
 * @property {Array<string>} [stale] fields not current: all while the link is lost, those not reported again since it came back (mode reads UNKNOWN until it is)
 * @property {EstimatorOut|null} [estimator]
 * @property {Array<string>|null} [sensors_unhealthy] SYS_STATUS sensors present and enabled but not healthy
 * @property {Object<string, number>} [message_ages_s] seconds since each source message (by MAVLink name) was last received
 * @property {LinkQualityOut|null} [link_quality]
 * @property {string|null} [lost_reason] how the server noticed the vehicle's loss, while `connected` is false ("nothing heard for 1.0 s", "simulated vehicle's process ended (killed by SIGKILL)"); null while it is connected
 * @property {ArmingChecksOut|null} [arming_checks] ready to fly: PX4's arming checks for the mode flown, and why not
 */

/**
 * @typedef {Object} VehicleSummaryOut
 * @property {number} id
 * @property {number} sysid
 * @property {string} type
 * @property {string} autopilot
 * @property {boolean} connected
 * @property {string} mode
 * @property {boolean} armed
 * @property {LinkOut} link
 */

/**
 * Every vehicle served, sent when the list changes.
 * @typedef {Object} VehiclesMessage
 * @property {"vehicles"} type
 * @property {Array<VehicleSummaryOut>} vehicles
 */

/**
 * A velocity in the body frame (forward, right, down) and a yaw rate (none: 0).
 * @typedef {Object} VelocityBodyBody
 * @property {"velocity_body"} type
 * @property {number} forward_m_s (m/s)
 * @property {number} right_m_s (m/s)
 * @property {number} down_m_s (m/s)
 * @property {number|null} [yaw_rate_deg_s]
 */

/**
 * A NED velocity with a yaw or a yaw rate (neither: keep the current heading).
 * @typedef {Object} VelocityNedBody
 * @property {"velocity_ned"} type
 * @property {number} north_m_s (m/s)
 * @property {number} east_m_s (m/s)
 * @property {number} down_m_s (m/s)
 * @property {number|null} [yaw_deg]
 * @property {number|null} [yaw_rate_deg_s]
 */

/**
 * @typedef {Object} VelocityNedOut
 * @property {number|null} north_m_s
 * @property {number|null} east_m_s
 * @property {number|null} down_m_s
 */

/**
 * @typedef {PositionNedBody|VelocityNedBody|VelocityBodyBody|AccelerationNedBody|PositionVelocityNedBody|PositionGlobalBody|AttitudeBody|BodyRatesBody|OffsetNedBody|OffsetBodyBody|RawLocalBody} SetpointBody
 */

/**
 * @typedef {StateMessage|StatusTextMessage|EventMessage|VehiclesMessage|SceneClickMessage} TelemetryMessage
 */

/**
 * @typedef {LeaseMessage|LeaseEndedMessage|TakeoverRequestedMessage|ControlErrorMessage|ResultMessage} ControlMessage
 */

export {};

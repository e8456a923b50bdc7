-- Simulator appointments and counterbalanced condition orders (see docs/scheduling.md).
-- Appointment times are the lab's local wall-clock time (TIMESTAMP without zone), as a lab books them.

CREATE SEQUENCE appointment_id_seq START 1;

CREATE TABLE appointments (
    appointment_id  BIGINT PRIMARY KEY DEFAULT nextval('appointment_id_seq'),
    participant_id  VARCHAR NOT NULL REFERENCES participants (participant_id),
    simulator       VARCHAR NOT NULL CHECK (length(simulator) BETWEEN 1 AND 40),
    starts_at       TIMESTAMP NOT NULL,
    ends_at         TIMESTAMP NOT NULL,
    status          VARCHAR NOT NULL DEFAULT 'booked'
                    CHECK (status IN ('booked', 'cancelled', 'no_show', 'attended')),
    protocol        VARCHAR NOT NULL,
    note            VARCHAR,
    created_at      TIMESTAMP NOT NULL DEFAULT (current_timestamp AT TIME ZONE 'UTC'),
    CHECK (ends_at > starts_at)
);

-- The condition order a participant of a multi-order protocol was assigned (one per participant).
CREATE TABLE order_assignments (
    participant_id  VARCHAR PRIMARY KEY REFERENCES participants (participant_id),
    protocol        VARCHAR NOT NULL,
    order_name      VARCHAR NOT NULL,
    assigned_at     TIMESTAMP NOT NULL DEFAULT (current_timestamp AT TIME ZONE 'UTC')
);

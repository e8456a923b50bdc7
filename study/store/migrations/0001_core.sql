-- Core tables of the pEDAS study store (see docs/store.md).
-- Timestamps are UTC (TIMESTAMP without zone). Enumerations are CHECK constraints so that the schema itself
-- refuses impossible values; the Python layer validates first to give a friendlier one-line reason.

CREATE TABLE participants (
    participant_id  VARCHAR PRIMARY KEY CHECK (regexp_full_match(participant_id, '^P[0-9]{3,}$')),
    age             INTEGER CHECK (age BETWEEN 16 AND 110),
    gender          VARCHAR CHECK (gender IN ('female', 'male', 'diverse', 'undisclosed')),
    license_years   INTEGER CHECK (license_years BETWEEN 0 AND 95),
    style           VARCHAR CHECK (style IN ('cautious', 'normal', 'sporty')),
    eco_familiarity INTEGER CHECK (eco_familiarity BETWEEN 1 AND 5),
    protocol        VARCHAR NOT NULL DEFAULT 'paper_v1',
    created_at      TIMESTAMP NOT NULL DEFAULT (current_timestamp AT TIME ZONE 'UTC'),
    -- a licence is held for at most (age - 16) years (16 = the youngest accompanied-driving age in Germany)
    CHECK (age IS NULL OR license_years IS NULL OR license_years <= age - 16)
);

-- One row per protocol phase a participant entered. ended_at/outcome are filled when the phase ends.
CREATE TABLE phase_events (
    participant_id  VARCHAR NOT NULL REFERENCES participants (participant_id),
    phase           VARCHAR NOT NULL,
    seq             INTEGER NOT NULL CHECK (seq >= 1),           -- position of the phase in the protocol
    started_at      TIMESTAMP NOT NULL,
    ended_at        TIMESTAMP,
    outcome         VARCHAR NOT NULL DEFAULT 'in_progress'
                    CHECK (outcome IN ('in_progress', 'completed', 'aborted')),
    note            VARCHAR,
    PRIMARY KEY (participant_id, phase),
    UNIQUE (participant_id, seq),
    CHECK ((outcome = 'in_progress') = (ended_at IS NULL)),
    CHECK (ended_at IS NULL OR ended_at >= started_at)
);

CREATE TABLE exclusions (
    participant_id  VARCHAR NOT NULL REFERENCES participants (participant_id),
    scope           VARCHAR NOT NULL CHECK (scope IN ('all', 'objective', 'subjective')),
    reason          VARCHAR NOT NULL CHECK (reason IN ('motion_sickness', 'technical_issue', 'incomplete_survey',
                                                       'withdrawn', 'other')),
    note            VARCHAR,
    created_at      TIMESTAMP NOT NULL DEFAULT (current_timestamp AT TIME ZONE 'UTC'),
    PRIMARY KEY (participant_id, scope)
);

CREATE SEQUENCE drive_id_seq START 1;

CREATE TABLE drives (
    drive_id        BIGINT PRIMARY KEY DEFAULT nextval('drive_id_seq'),
    participant_id  VARCHAR NOT NULL REFERENCES participants (participant_id),
    condition       VARCHAR NOT NULL CHECK (condition IN ('baseline', 'pedas')),
    source          VARCHAR NOT NULL CHECK (source IN ('import', 'simulation')),
    route           VARCHAR,
    checksum        VARCHAR NOT NULL CHECK (regexp_full_match(checksum, '^[0-9a-f]{64}$')),   -- sha256 hex
    n_samples       BIGINT NOT NULL CHECK (n_samples >= 2),
    file_name       VARCHAR,
    duration_s      DOUBLE CHECK (duration_s > 0),
    distance_m      DOUBLE CHECK (distance_m >= 0),
    seed            BIGINT,
    meta            VARCHAR,                                   -- JSON: generator settings of a simulated drive
    created_at      TIMESTAMP NOT NULL DEFAULT (current_timestamp AT TIME ZONE 'UTC'),
    UNIQUE (participant_id, condition)
);

-- The samples of a drive. No key and no foreign key on purpose: an index over millions of rows makes
-- bulk import ~7x slower, and DuckDB cannot delete a referenced parent row in the transaction that deletes
-- its children (needed by `drive import --replace`). The Store writes samples only together with their
-- drives row in one transaction (idx = 0..n_samples-1).
CREATE TABLE drive_samples (
    drive_id        BIGINT NOT NULL,
    idx             INTEGER NOT NULL CHECK (idx >= 0),
    t               DOUBLE NOT NULL,                           -- s
    s               DOUBLE NOT NULL,                           -- m along the route
    v               DOUBLE NOT NULL CHECK (v BETWEEN 0 AND 70),  -- m/s
    segment         VARCHAR NOT NULL CHECK (segment IN ('urban', 'highway')),
    speed_limit     DOUBLE NOT NULL CHECK (speed_limit > 0 AND speed_limit <= 70),  -- m/s
    a               DOUBLE,                                    -- m/s^2
    grade           DOUBLE,                                    -- rad
    ft              DOUBLE,                                    -- N traction force
    fb              DOUBLE,                                    -- N braking force
    p_batt          DOUBLE,                                    -- W battery power
    tl_id           VARCHAR,                                   -- next traffic light ahead, NULL when none
    tl_state        VARCHAR CHECK (tl_state IN ('green', 'yellow', 'red')),
    d_tl            DOUBLE,                                    -- m to its stop line
    leader_gap      DOUBLE,                                    -- m
    leader_v        DOUBLE,                                    -- m/s
    v_advice        DOUBLE,                                    -- m/s
    controller      VARCHAR CHECK (controller IN ('rt', 'cf', 'none')),
    hud_arrow       TINYINT CHECK (hud_arrow IN (-1, 0, 1)),
    hud_in_band     BOOLEAN,
    warning         BOOLEAN
);

-- The survey codebooks (study/instruments/*.csv), loaded by the Store when it opens a store.
CREATE TABLE instruments (
    instrument      VARCHAR PRIMARY KEY,
    version         VARCHAR NOT NULL,
    n_items         INTEGER NOT NULL CHECK (n_items > 0),
    loaded_at       TIMESTAMP NOT NULL DEFAULT (current_timestamp AT TIME ZONE 'UTC')
);

CREATE TABLE items (
    instrument      VARCHAR NOT NULL REFERENCES instruments (instrument),
    item_id         VARCHAR NOT NULL,
    position        INTEGER NOT NULL CHECK (position >= 1),
    construct       VARCHAR NOT NULL,
    section         VARCHAR,
    text            VARCHAR NOT NULL,
    response_type   VARCHAR NOT NULL,                          -- likert5 | semantic5 | text | ... (codebook)
    scale_min       INTEGER,
    scale_max       INTEGER,
    anchor_low      VARCHAR,
    anchor_high     VARCHAR,
    choices         VARCHAR,
    reverse_scored  BOOLEAN NOT NULL,
    required        BOOLEAN NOT NULL,
    PRIMARY KEY (instrument, item_id),
    CHECK (scale_min IS NULL OR scale_max > scale_min)
);

-- Survey answers: one row per participant, item and entry round (double data entry uses rounds 1 and 2).
CREATE TABLE responses (
    participant_id  VARCHAR NOT NULL REFERENCES participants (participant_id),
    instrument      VARCHAR NOT NULL,
    item_id         VARCHAR NOT NULL,
    entry_round     INTEGER NOT NULL DEFAULT 1 CHECK (entry_round >= 1),
    value           INTEGER CHECK (value BETWEEN 1 AND 10),
    text            VARCHAR,
    entered_by      VARCHAR,
    entered_at      TIMESTAMP NOT NULL DEFAULT (current_timestamp AT TIME ZONE 'UTC'),
    PRIMARY KEY (participant_id, instrument, item_id, entry_round),
    FOREIGN KEY (instrument, item_id) REFERENCES items (instrument, item_id)
);

CREATE SEQUENCE audit_id_seq START 1;

-- Every insert/update/delete of research data made through the Store API. row_key/old/new are JSON text.
CREATE TABLE audit_log (
    audit_id        BIGINT PRIMARY KEY DEFAULT nextval('audit_id_seq'),
    "at"            TIMESTAMP NOT NULL,
    actor           VARCHAR NOT NULL,
    action          VARCHAR NOT NULL CHECK (action IN ('insert', 'update', 'delete')),
    table_name      VARCHAR NOT NULL,
    row_key         VARCHAR NOT NULL,
    old             VARCHAR,
    new             VARCHAR
);

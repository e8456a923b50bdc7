-- The study as data (docs/study_folder.md): a store holds the definition of the study it serves (versioned,
-- with its hash), participants carry the attributes that study declares, and the values the paper's study fixed
-- in the schema (ids P001, conditions baseline|pedas, segments urban|highway, the five demographics, answers
-- 1..10) are checked against the stored definition by the Python layer instead. DuckDB cannot drop a column or a
-- CHECK of a table that others reference, so the tables are rebuilt: copied aside, dropped children first,
-- recreated, copied back. The old demographic columns become participant_attributes rows.

CREATE TABLE study_definitions (
    version         INTEGER PRIMARY KEY CHECK (version >= 1),
    study_id        VARCHAR NOT NULL,
    title           VARCHAR NOT NULL,
    hash            VARCHAR NOT NULL CHECK (regexp_full_match(hash, '^[0-9a-f]{64}$')),
    files           VARCHAR NOT NULL,                          -- JSON {relative path: text} as checked
    source          VARCHAR,                                   -- the folder it was read from (informative)
    loaded_at       TIMESTAMP NOT NULL,
    loaded_by       VARCHAR NOT NULL
);

CREATE TEMP TABLE _participants AS SELECT * FROM participants;
CREATE TEMP TABLE _phase_events AS SELECT * FROM phase_events;
CREATE TEMP TABLE _exclusions AS SELECT * FROM exclusions;
CREATE TEMP TABLE _drives AS SELECT * FROM drives;
CREATE TEMP TABLE _responses AS SELECT * FROM responses;
CREATE TEMP TABLE _appointments AS SELECT * FROM appointments;
CREATE TEMP TABLE _order_assignments AS SELECT * FROM order_assignments;
CREATE TEMP TABLE _survey_resolutions AS SELECT * FROM survey_resolutions;

DROP TABLE order_assignments;
DROP TABLE appointments;
DROP TABLE responses;
DROP TABLE drives;
DROP TABLE exclusions;
DROP TABLE phase_events;
DROP TABLE participants;
DROP TABLE survey_resolutions;

CREATE TABLE participants (
    participant_id  VARCHAR PRIMARY KEY CHECK (length(participant_id) BETWEEN 1 AND 64
                                               AND NOT regexp_matches(participant_id, '\s')),
    protocol        VARCHAR NOT NULL,
    study_version   INTEGER,                                   -- study_definitions.version at registration
    created_at      TIMESTAMP NOT NULL DEFAULT (current_timestamp AT TIME ZONE 'UTC')
);

-- One row per participant and declared attribute with a value; values as text, typed by the definition.
CREATE TABLE participant_attributes (
    participant_id  VARCHAR NOT NULL REFERENCES participants (participant_id),
    attribute       VARCHAR NOT NULL,
    value           VARCHAR NOT NULL,
    PRIMARY KEY (participant_id, attribute)
);

CREATE TABLE phase_events (
    participant_id  VARCHAR NOT NULL REFERENCES participants (participant_id),
    phase           VARCHAR NOT NULL,
    seq             INTEGER NOT NULL CHECK (seq >= 1),
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

CREATE TABLE drives (
    drive_id        BIGINT PRIMARY KEY DEFAULT nextval('drive_id_seq'),
    participant_id  VARCHAR NOT NULL REFERENCES participants (participant_id),
    condition       VARCHAR NOT NULL CHECK (length(condition) BETWEEN 1 AND 64),   -- a declared condition
    source          VARCHAR NOT NULL CHECK (source IN ('import', 'simulation')),
    route           VARCHAR,
    checksum        VARCHAR NOT NULL CHECK (regexp_full_match(checksum, '^[0-9a-f]{64}$')),
    n_samples       BIGINT NOT NULL CHECK (n_samples >= 2),
    file_name       VARCHAR,
    duration_s      DOUBLE CHECK (duration_s > 0),
    distance_m      DOUBLE CHECK (distance_m >= 0),
    seed            BIGINT,
    meta            VARCHAR,
    created_at      TIMESTAMP NOT NULL DEFAULT (current_timestamp AT TIME ZONE 'UTC'),
    UNIQUE (participant_id, condition)
);

CREATE TABLE responses (
    participant_id  VARCHAR NOT NULL REFERENCES participants (participant_id),
    instrument      VARCHAR NOT NULL,
    item_id         VARCHAR NOT NULL,
    entry_round     INTEGER NOT NULL DEFAULT 1 CHECK (entry_round >= 1),
    value           INTEGER,                                   -- within the item's declared range (codebook)
    text            VARCHAR,
    entered_by      VARCHAR,
    entered_at      TIMESTAMP NOT NULL DEFAULT (current_timestamp AT TIME ZONE 'UTC'),
    PRIMARY KEY (participant_id, instrument, item_id, entry_round),
    FOREIGN KEY (instrument, item_id) REFERENCES items (instrument, item_id)
);

CREATE TABLE survey_resolutions (
    participant_id  VARCHAR NOT NULL,
    instrument      VARCHAR NOT NULL,
    item_id         VARCHAR NOT NULL,
    value           INTEGER,
    text            VARCHAR,
    note            VARCHAR,
    resolved_by     VARCHAR NOT NULL,
    resolved_at     TIMESTAMP NOT NULL,
    PRIMARY KEY (participant_id, instrument, item_id)
);

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

CREATE TABLE order_assignments (
    participant_id  VARCHAR PRIMARY KEY REFERENCES participants (participant_id),
    protocol        VARCHAR NOT NULL,
    order_name      VARCHAR NOT NULL,
    assigned_at     TIMESTAMP NOT NULL DEFAULT (current_timestamp AT TIME ZONE 'UTC')
);

INSERT INTO participants SELECT participant_id, protocol, NULL, created_at FROM _participants;
INSERT INTO participant_attributes
    SELECT participant_id, attribute, value FROM (
        SELECT participant_id, 'age' AS attribute, CAST(age AS VARCHAR) AS value FROM _participants
        UNION ALL SELECT participant_id, 'gender', gender FROM _participants
        UNION ALL SELECT participant_id, 'license_years', CAST(license_years AS VARCHAR) FROM _participants
        UNION ALL SELECT participant_id, 'style', style FROM _participants
        UNION ALL SELECT participant_id, 'eco_familiarity', CAST(eco_familiarity AS VARCHAR) FROM _participants)
    WHERE value IS NOT NULL;
INSERT INTO phase_events SELECT * FROM _phase_events;
INSERT INTO exclusions SELECT * FROM _exclusions;
INSERT INTO drives SELECT * FROM _drives;
INSERT INTO responses SELECT * FROM _responses;
INSERT INTO survey_resolutions SELECT * FROM _survey_resolutions;
INSERT INTO appointments SELECT * FROM _appointments;
INSERT INTO order_assignments SELECT * FROM _order_assignments;

DROP TABLE _participants;
DROP TABLE _phase_events;
DROP TABLE _exclusions;
DROP TABLE _drives;
DROP TABLE _responses;
DROP TABLE _appointments;
DROP TABLE _order_assignments;
DROP TABLE _survey_resolutions;

-- free segment labels (declared by the study's route); speed bounds stay physical
CREATE TABLE _drive_samples_new (
    drive_id        BIGINT NOT NULL,
    idx             INTEGER NOT NULL CHECK (idx >= 0),
    t               DOUBLE NOT NULL,
    s               DOUBLE NOT NULL,
    v               DOUBLE NOT NULL CHECK (v BETWEEN 0 AND 70),
    segment         VARCHAR NOT NULL CHECK (length(segment) BETWEEN 1 AND 64),
    speed_limit     DOUBLE NOT NULL CHECK (speed_limit > 0 AND speed_limit <= 70),
    a               DOUBLE,
    grade           DOUBLE,
    ft              DOUBLE,
    fb              DOUBLE,
    p_batt          DOUBLE,
    tl_id           VARCHAR,
    tl_state        VARCHAR CHECK (tl_state IN ('green', 'yellow', 'red')),
    d_tl            DOUBLE,
    leader_gap      DOUBLE,
    leader_v        DOUBLE,
    v_advice        DOUBLE,
    controller      VARCHAR CHECK (controller IN ('rt', 'cf', 'none')),
    hud_arrow       TINYINT CHECK (hud_arrow IN (-1, 0, 1)),
    hud_in_band     BOOLEAN,
    warning         BOOLEAN
);
INSERT INTO _drive_samples_new SELECT * FROM drive_samples;
DROP TABLE drive_samples;
ALTER TABLE _drive_samples_new RENAME TO drive_samples;

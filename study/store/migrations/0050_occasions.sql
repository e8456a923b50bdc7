-- Questionnaire occasions and drives outside conditions (docs/survey.md "Occasions", docs/store.md "Drive logs").
--
-- An answer is keyed by participant, instrument, OCCASION, item and entry round: the occasion is the protocol phase
-- in which the questionnaire was answered (e.g. survey_after_visual), so one instrument can be answered several
-- times by one participant. The survey tables get an `occasion` column after their existing columns and it joins
-- their keys. Rows stored before this migration get the empty text here; `Store.open` then sets them to the
-- study's single questionnaire phase (study.occasions.fill_migrated: the stored study is TOML and JSON text, which
-- this SQL cannot read), and `init --study` does the same for a store that had no study yet.
--
-- A drive may belong to a protocol phase without a condition (familiarisation, practice): `drives.condition`
-- becomes nullable and `drives.phase` names such a drive's phase (NULL for a condition's drive, which its
-- condition names). Both unique keys hold: one drive per (participant, condition), one per (participant, phase).
--
-- DuckDB cannot change a key or a NOT NULL of a table in place, so the tables are copied aside and rebuilt (none
-- of them is referenced by another table).

CREATE TEMP TABLE _responses AS SELECT * FROM responses;
CREATE TEMP TABLE _survey_tokens AS SELECT * FROM survey_tokens;
CREATE TEMP TABLE _survey_drafts AS SELECT * FROM survey_drafts;
CREATE TEMP TABLE _survey_submissions AS SELECT * FROM survey_submissions;
CREATE TEMP TABLE _survey_resolutions AS SELECT * FROM survey_resolutions;
CREATE TEMP TABLE _drives AS SELECT * FROM drives;

DROP TABLE responses;
DROP TABLE survey_tokens;
DROP TABLE survey_drafts;
DROP TABLE survey_submissions;
DROP TABLE survey_resolutions;
DROP TABLE drives;

CREATE TABLE responses (
    participant_id  VARCHAR NOT NULL REFERENCES participants (participant_id),
    instrument      VARCHAR NOT NULL,
    item_id         VARCHAR NOT NULL,
    entry_round     INTEGER NOT NULL DEFAULT 1 CHECK (entry_round >= 1),
    value           INTEGER,                                   -- within the item's declared range (codebook)
    text            VARCHAR,
    entered_by      VARCHAR,
    entered_at      TIMESTAMP NOT NULL DEFAULT (current_timestamp AT TIME ZONE 'UTC'),
    occasion        VARCHAR NOT NULL CHECK (length(occasion) <= 64),   -- the questionnaire phase answered in
    PRIMARY KEY (participant_id, instrument, occasion, item_id, entry_round),
    FOREIGN KEY (instrument, item_id) REFERENCES items (instrument, item_id)
);

CREATE TABLE survey_tokens (
    token_hash      VARCHAR PRIMARY KEY CHECK (regexp_full_match(token_hash, '^[0-9a-f]{64}$')),
    participant_id  VARCHAR NOT NULL,
    instrument      VARCHAR NOT NULL,
    issued_at       TIMESTAMP NOT NULL,
    issued_by       VARCHAR NOT NULL,
    revoked_at      TIMESTAMP,
    occasion        VARCHAR NOT NULL CHECK (length(occasion) <= 64)
);

CREATE TABLE survey_drafts (
    participant_id  VARCHAR NOT NULL,
    instrument      VARCHAR NOT NULL,
    item_id         VARCHAR NOT NULL,
    value           INTEGER,
    text            VARCHAR,
    saved_at        TIMESTAMP NOT NULL,
    occasion        VARCHAR NOT NULL CHECK (length(occasion) <= 64),
    PRIMARY KEY (participant_id, instrument, occasion, item_id)
);

CREATE TABLE survey_submissions (
    participant_id  VARCHAR NOT NULL,
    instrument      VARCHAR NOT NULL,
    entry_round     INTEGER NOT NULL CHECK (entry_round IN (1, 2)),
    source          VARCHAR NOT NULL CHECK (source IN ('web', 'import', 'entry')),
    double_entry    BOOLEAN NOT NULL,
    submitted_by    VARCHAR NOT NULL,
    submitted_at    TIMESTAMP NOT NULL,
    occasion        VARCHAR NOT NULL CHECK (length(occasion) <= 64),
    PRIMARY KEY (participant_id, instrument, occasion, entry_round),
    CHECK (entry_round = 1 OR double_entry)
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
    occasion        VARCHAR NOT NULL CHECK (length(occasion) <= 64),
    PRIMARY KEY (participant_id, instrument, occasion, item_id)
);

CREATE TABLE drives (
    drive_id        BIGINT PRIMARY KEY DEFAULT nextval('drive_id_seq'),
    participant_id  VARCHAR NOT NULL REFERENCES participants (participant_id),
    condition       VARCHAR CHECK (length(condition) BETWEEN 1 AND 64),   -- a declared condition; NULL: see phase
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
    phase           VARCHAR CHECK (length(phase) BETWEEN 1 AND 64),       -- the drive phase of a drive without one
    UNIQUE (participant_id, condition),
    UNIQUE (participant_id, phase),
    CHECK ((condition IS NULL) <> (phase IS NULL))
);

INSERT INTO responses SELECT *, '' FROM _responses;
INSERT INTO survey_tokens SELECT *, '' FROM _survey_tokens;
INSERT INTO survey_drafts SELECT *, '' FROM _survey_drafts;
INSERT INTO survey_submissions SELECT *, '' FROM _survey_submissions;
INSERT INTO survey_resolutions SELECT *, '' FROM _survey_resolutions;
INSERT INTO drives SELECT *, NULL FROM _drives;

DROP TABLE _responses;
DROP TABLE _survey_tokens;
DROP TABLE _survey_drafts;
DROP TABLE _survey_submissions;
DROP TABLE _survey_resolutions;
DROP TABLE _drives;

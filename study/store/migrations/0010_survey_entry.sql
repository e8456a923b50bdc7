-- Survey web form and survey data entry (see docs/survey.md). The answers themselves live in the core
-- `responses` table; these tables hold what is needed around them. No foreign keys: the survey code checks
-- participants and instruments itself and gives a one-line reason.

-- One row per participant link. Only the SHA-256 of the link token is stored; issuing a new link for a
-- participant revokes the earlier ones (a lost tablet cannot be used to change the answers later).
CREATE TABLE survey_tokens (
    token_hash      VARCHAR PRIMARY KEY CHECK (regexp_full_match(token_hash, '^[0-9a-f]{64}$')),
    participant_id  VARCHAR NOT NULL,
    instrument      VARCHAR NOT NULL,
    issued_at       TIMESTAMP NOT NULL,
    issued_by       VARCHAR NOT NULL,
    revoked_at      TIMESTAMP
);

-- Answers a participant has given on the web form but not yet submitted (kept server-side so a reload or a
-- crashed tablet resumes). Not research data until submitted: not audited, deleted by the submission.
CREATE TABLE survey_drafts (
    participant_id  VARCHAR NOT NULL,
    instrument      VARCHAR NOT NULL,
    item_id         VARCHAR NOT NULL,
    value           INTEGER,
    text            VARCHAR,
    saved_at        TIMESTAMP NOT NULL,
    PRIMARY KEY (participant_id, instrument, item_id)
);

-- One row per complete entry round in `responses`: where it came from and whether it is one half of a
-- double data entry (paper forms: round 1 and round 2 by two people) or a single electronic entry that
-- counts as final by itself (participant web form, import of an electronic export).
CREATE TABLE survey_submissions (
    participant_id  VARCHAR NOT NULL,
    instrument      VARCHAR NOT NULL,
    entry_round     INTEGER NOT NULL CHECK (entry_round IN (1, 2)),
    source          VARCHAR NOT NULL CHECK (source IN ('web', 'import', 'entry')),
    double_entry    BOOLEAN NOT NULL,
    submitted_by    VARCHAR NOT NULL,
    submitted_at    TIMESTAMP NOT NULL,
    PRIMARY KEY (participant_id, instrument, entry_round),
    CHECK (entry_round = 1 OR double_entry)
);

-- The final value of an item where the two entries of a double data entry differ (checked against the paper
-- form). value/text both NULL = the answer is missing on the form.
CREATE TABLE survey_resolutions (
    participant_id  VARCHAR NOT NULL,
    instrument      VARCHAR NOT NULL,
    item_id         VARCHAR NOT NULL,
    value           INTEGER CHECK (value BETWEEN 1 AND 10),
    text            VARCHAR,
    note            VARCHAR,
    resolved_by     VARCHAR NOT NULL,
    resolved_at     TIMESTAMP NOT NULL,
    PRIMARY KEY (participant_id, instrument, item_id)
);

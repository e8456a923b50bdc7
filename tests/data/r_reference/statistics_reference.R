# Reference values for tests/analysis/test_statistics_reference.py: the statistics of the report's reviewer tables
# (analysis/survey/paired.py, analysis/survey/diagnostics.py, analysis/survey/cfa.py rmsea_ci) computed with base R,
# car, lmtest and lavaan, written to statistics_reference.csv beside this script (columns dataset, quantity, key,
# value; 17 significant digits).
#
#   Rscript tests/data/r_reference/statistics_reference.R      (from anywhere; needs lavaan, car, lmtest)
#
# Data sets:
# * paper:    data/reference/survey.csv (the reconstructed survey of the paper's study; its md5 is recorded so that the
#             test notices a regenerated file), composites = item means of the final model's items (model.lav);
# * lk:       tests/data/lane_keeping/survey.csv with age from participants.csv (EE3 reversed: 8 - x);
# * drives:   paper_drive_pairs.csv beside this script: the per-participant KPIs of the paper's study's simulated
#             reference cohort (baseline and pEDAS drive), as the report writes them (drives/per_participant.csv);
# * takeover: tests/data/takeover/scores.csv (SUS, raw TLX, trust after each drive) and takeover_times.csv beside
#             this script (takeover time per participant and condition from the seeded logs of tests/takeover_logs.py).
# Conventions:
# * regressions: each model line of model.lav is one step (all its predictors), a blank line starts the next model;
#   lm() per step on the complete cases; Shapiro-Wilk shapiro.test(residuals); lmtest::bptest(fit) (studentized);
#   cooks.distance(fit); car::vif(fit) (steps with two or more predictors); beta CI = confint() of lm() on scale()d
#   variables; f^2 = dR^2 / (1 - R^2) with its 95 % CI by uniroot on pf(F, df1, df2, ncp) (tol 1e-12), ncp / (df1 +
#   df2 + 1);
# * CFA: cfa(estimator = "ML") of the initial (every item of the six constructs) and final (model.lav) measurement
#   model; fitMeasures chisq, df, rmsea, rmsea.ci.lower, rmsea.ci.upper where lavaan converges (not on the paper's
#   initial stage); and the 90 % limits again from lavaan's chisq by uniroot on pchisq(chisq, df, ncp) with tol 1e-12
#   (lavaan's own search stops at tol ~1e-4); the grid: lavaan:::lav_fit_rmsea_ci and the exact roots for a grid of
#   (chi^2, df, N);
# * paired: t.test(a, b, paired = TRUE) (mean difference, 95 % CI, t, df, p); d_z = mean(a - b) / sd(a - b);
#   wilcox.test of the differences put on the grid of 1e-9 x max |a, b| (round((a - b) / res)), R's defaults
#   otherwise (exact without ties and zeros for n < 50, else normal with continuity correction); and wilcox.test(a, b,
#   paired = TRUE) on the raw values (wilcoxon_raw: float noise in fractional scores can split ties there);
# * mixed ANOVA: summary(aov(value ~ condition * group + Error(participant / condition))) (drives: group = style).

args <- commandArgs(trailingOnly = FALSE)
script <- sub("^--file=", "", args[grep("^--file=", args)])
here <- if (length(script)) dirname(normalizePath(script)) else "tests/data/r_reference"
repo <- normalizePath(file.path(here, "..", "..", ".."))
suppressPackageStartupMessages({library(lavaan); library(car); library(lmtest)})

num <- function(x) if (is.na(x)) "" else sprintf("%.17g", x)
out <- character(0)
put <- function(dataset, quantity, key, value) {
  out <<- c(out, sprintf("%s,%s,%s,%s", dataset, quantity, key, num(as.numeric(value))))
}

model_lines <- function(study) {
  lines <- trimws(sub("#.*$", "", readLines(file.path(repo, "studies", study, "model.lav"))))
  lines
}
measurement_of <- function(lines) lines[grepl("=~", lines)]
models_of <- function(lines) {
  models <- list(); cur <- list(); started <- FALSE
  for (ln in lines) {
    if (grepl("=~", ln) || grepl("[<>]", ln)) next
    if (ln == "") { if (length(cur)) { models[[length(models) + 1]] <- cur; cur <- list() }; next }
    if (grepl("~", ln, fixed = TRUE)) {
      parts <- strsplit(ln, "~", fixed = TRUE)[[1]]
      preds <- sub("^.*\\*", "", trimws(strsplit(parts[2], "+", fixed = TRUE)[[1]]))
      cur[[length(cur) + 1]] <- list(dv = trimws(parts[1]), preds = preds)
    }
  }
  if (length(cur)) models[[length(models) + 1]] <- cur
  models
}
items_of <- function(measurement) {
  cs <- list()
  for (ln in measurement) {
    parts <- strsplit(ln, "=~", fixed = TRUE)[[1]]
    cs[[trimws(parts[1])]] <- trimws(strsplit(parts[2], "+", fixed = TRUE)[[1]])
  }
  cs
}

f2_ci <- function(f, df1, df2, level = 0.95) {
  a <- (1 - level) / 2
  lim <- function(target) {
    g <- function(l) pf(f, df1, df2, ncp = l) - target
    if (g(0) < 0) return(0)
    hi <- max(10, 2 * f * df1); while (g(hi) > 0) hi <- hi * 2
    uniroot(g, c(0, hi), tol = 1e-12)$root / (df1 + df2 + 1)
  }
  c(lim(1 - a), lim(a))
}

regressions <- function(tag, data, models) {
  for (m in seq_along(models)) {
    r2_old <- 0
    for (s in seq_along(models[[m]])) {
      st <- models[[m]][[s]]
      d <- data[complete.cases(data[, c(st$dv, st$preds)]), ]
      fit <- lm(reformulate(st$preds, response = st$dv), data = d)
      key <- paste0(m, ".", s)
      sw <- shapiro.test(residuals(fit))
      put(tag, "shapiro_w", key, sw$statistic); put(tag, "shapiro_p", key, sw$p.value)
      bp <- bptest(fit)
      put(tag, "bp", key, bp$statistic); put(tag, "bp_df", key, bp$parameter); put(tag, "bp_p", key, bp$p.value)
      cd <- cooks.distance(fit)
      for (i in seq_along(cd)) put(tag, "cooks", paste0(key, ".", d$participant_id[i]), cd[[i]])
      if (length(st$preds) > 1) { v <- vif(fit); for (p in names(v)) put(tag, "vif", paste0(key, ".", p), v[[p]]) }
      z <- as.data.frame(scale(d[, c(st$dv, st$preds)]))
      ci <- confint(lm(reformulate(st$preds, response = st$dv), data = z))
      for (p in st$preds) {
        put(tag, "beta_ci_low", paste0(key, ".", p), ci[p, 1]); put(tag, "beta_ci_high", paste0(key, ".", p), ci[p, 2])
      }
      r2 <- summary(fit)$r.squared
      df1 <- length(st$preds) - (if (s > 1) length(models[[m]][[s - 1]]$preds) else 0)
      df2 <- fit$df.residual
      fch <- ((r2 - r2_old) / df1) / ((1 - r2) / df2)
      put(tag, "f2", key, (r2 - r2_old) / (1 - r2))
      lims <- f2_ci(fch, df1, df2)
      put(tag, "f2_ci_low", key, lims[1]); put(tag, "f2_ci_high", key, lims[2])
      r2_old <- r2
    }
  }
}

rmsea_exact <- function(X2, df, N, level = 0.90) {
  lo <- function(l) pchisq(X2, df, ncp = l) - (1 - (1 - level) / 2)
  up <- function(l) pchisq(X2, df, ncp = l) - (1 - level) / 2
  l_lo <- if (lo(0) < 0) 0 else uniroot(lo, c(0, X2), tol = 1e-12)$root
  NR <- max(N, 4 * X2)
  l_up <- if (up(NR) > 0 || up(0) < 0) 0 else uniroot(up, c(0, NR), tol = 1e-12)$root
  c(sqrt(l_lo / (N * df)), sqrt(l_up / (N * df)))
}

cfa_fits <- function(tag, data, stages) {
  for (st in names(stages)) {
    f <- suppressWarnings(cfa(stages[[st]], data = data, estimator = "ML"))
    put(tag, "cfa_converged", st, as.numeric(lavInspect(f, "converged")))
    if (!lavInspect(f, "converged")) next   # lavaan gives no fit measures (the paper's initial stage: Heywood case)
    fm <- fitMeasures(f, c("chisq", "df", "rmsea", "rmsea.ci.lower", "rmsea.ci.upper", "ntotal"))
    for (q in names(fm)) put(tag, paste0("cfa_", q), st, fm[[q]])
    ex <- rmsea_exact(fm[["chisq"]], fm[["df"]], fm[["ntotal"]])
    put(tag, "cfa_rmsea_ci_exact_low", st, ex[1]); put(tag, "cfa_rmsea_ci_exact_high", st, ex[2])
  }
}

paired <- function(tag, key, a, b) {
  ok <- !(is.na(a) | is.na(b)); a <- a[ok]; b <- b[ok]
  d <- a - b
  if (sd(d) == 0) return(invisible())
  tt <- t.test(a, b, paired = TRUE)
  put(tag, "mean_diff", key, tt$estimate); put(tag, "ci_low", key, tt$conf.int[1]); put(tag, "ci_high", key, tt$conf.int[2])
  put(tag, "t", key, tt$statistic); put(tag, "df", key, tt$parameter); put(tag, "p_t", key, tt$p.value)
  put(tag, "dz", key, mean(d) / sd(d))
  res <- 1e-9 * max(abs(c(a, b)))
  w <- suppressWarnings(wilcox.test(round(d / res)))
  put(tag, "v", key, w$statistic); put(tag, "p_wilcoxon", key, w$p.value)
  put(tag, "wilcoxon_exact", key, as.numeric(grepl("exact", w$method)))
  wr <- suppressWarnings(wilcox.test(a, b, paired = TRUE))
  put(tag, "v_raw", key, wr$statistic); put(tag, "p_wilcoxon_raw", key, wr$p.value)
}

mixed <- function(tag, key, participant, group, a, b) {
  ok <- !(is.na(a) | is.na(b))
  n <- sum(ok)
  d <- data.frame(participant = factor(rep(participant[ok], 2)), group = factor(rep(group[ok], 2)),
                  condition = factor(rep(c("a", "b"), each = n)), value = c(a[ok], b[ok]))
  s <- summary(aov(value ~ condition * group + Error(participant / condition), data = d))
  between <- s[["Error: participant"]][[1]]
  within <- s[["Error: participant:condition"]][[1]]
  rn <- trimws(rownames(within))
  put(tag, "anova_f_group", key, between[trimws(rownames(between)) == "group", "F value"])
  put(tag, "anova_p_group", key, between[trimws(rownames(between)) == "group", "Pr(>F)"])
  put(tag, "anova_f_condition", key, within[rn == "condition", "F value"])
  put(tag, "anova_p_condition", key, within[rn == "condition", "Pr(>F)"])
  put(tag, "anova_f_interaction", key, within[rn == "condition:group", "F value"])
  put(tag, "anova_p_interaction", key, within[rn == "condition:group", "Pr(>F)"])
}

# ---- lavaan's own RMSEA interval function on a grid of (chi^2, df, N)
for (X2 in c(5, 20, 40, 80, 175.97, 329.78)) for (df in c(1, 5, 20, 137)) for (N in c(24, 40, 200)) {
  ci <- lavaan:::lav_fit_rmsea_ci(X2 = X2, df = df, N = N)
  ex <- rmsea_exact(X2, df, N)
  key <- paste(X2, df, N, sep = "/")
  put("grid", "lavaan_low", key, ci$rmsea.ci.lower); put("grid", "lavaan_high", key, ci$rmsea.ci.upper)
  put("grid", "exact_low", key, ex[1]); put("grid", "exact_high", key, ex[2])
}

# ---- the paper's reference survey
survey_path <- file.path(repo, "data", "reference", "survey.csv")
put("paper", "input_md5", "survey", NA)
out[length(out)] <- sprintf("paper,input_md5,survey,%s", unname(tools::md5sum(survey_path)))
paper <- read.csv(survey_path, stringsAsFactors = FALSE, colClasses = c(participant_id = "character"))
lines <- model_lines("pedas_paper")
cs <- items_of(measurement_of(lines))
initial_items <- grep("^(PU|PEoU|ATT|PBC|SN|BI)[0-9]+$", names(paper), value = TRUE)
initial <- paste(vapply(names(cs), function(cn) paste(cn, "=~", paste(grep(paste0("^", cn, "[0-9]+$"),
                 initial_items, value = TRUE), collapse = " + ")), ""), collapse = "\n")
cfa_fits("paper", paper, list(initial = initial, final = paste(measurement_of(lines), collapse = "\n")))
for (cn in names(cs)) paper[[cn]] <- rowMeans(paper[, cs[[cn]]])
regressions("paper", paper, models_of(lines))

# ---- the lane-keeping example study
lk <- read.csv(file.path(repo, "tests", "data", "lane_keeping", "survey.csv"), stringsAsFactors = FALSE)
people <- read.csv(file.path(repo, "tests", "data", "lane_keeping", "participants.csv"), stringsAsFactors = FALSE)
lk$EE3 <- 8 - lk$EE3
lk$age <- people$age[match(lk$participant_id, people$participant_id)]
lines <- model_lines("lane_keeping")
cs <- items_of(measurement_of(lines))
cfa_fits("lk", lk, list(final = paste(measurement_of(lines), collapse = "\n")))
for (cn in names(cs)) lk[[cn]] <- rowMeans(lk[, cs[[cn]]])
regressions("lk", lk, models_of(lines))

# ---- paired comparisons: the paper's drives
drives <- read.csv(file.path(here, "paper_drive_pairs.csv"), stringsAsFactors = FALSE)
for (a in grep("_baseline", names(drives), value = TRUE)) {
  b <- sub("_baseline", "_pedas", a)
  key <- sub("_baseline", "", a)
  paired("drives", key, drives[[a]], drives[[b]])
  if (sd(drives[[a]] - drives[[b]], na.rm = TRUE) > 0)
    mixed("drives", key, drives$participant_id, drives$style, drives[[a]], drives[[b]])
}

# ---- paired comparisons: the takeover study (complete participants, every pair of conditions)
scores <- read.csv(file.path(repo, "tests", "data", "takeover", "scores.csv"), stringsAsFactors = FALSE)
times <- read.csv(file.path(here, "takeover_times.csv"), stringsAsFactors = FALSE)
long <- merge(scores, times, by = c("participant", "condition"))
levels <- c("none", "visual", "audiovisual")
counts <- table(long$participant)
complete_ids <- sort(names(counts)[counts == length(levels)])
for (v in c("sus", "tlx", "trust", "takeover_time")) for (i in 1:2) for (j in (i + 1):3) {
  get <- function(l) long[long$condition == l, ][match(complete_ids, long$participant[long$condition == l]), v]
  paired("takeover", paste0(v, ".", levels[i], "-", levels[j]), get(levels[i]), get(levels[j]))
}

writeLines(c("dataset,quantity,key,value", out), file.path(here, "statistics_reference.csv"))
cat("lavaan", as.character(packageVersion("lavaan")), "car", as.character(packageVersion("car")), "lmtest",
    as.character(packageVersion("lmtest")), ":", length(out), "values written to",
    file.path(here, "statistics_reference.csv"), "\n")

# Reference values for tests/analysis/test_extended_reference.py: the extended acceptance statistics (analysis/extended.py)
# computed with lavaan, semTools and base R, written to extended_reference.csv beside this script
# (columns dataset, quantity, key, value; 17 significant digits).
#
#   Rscript tests/data/r_reference/extended_reference.R      (from the repository root; needs lavaan, semTools)
#
# Data sets:
# * paper: survey.csv beside this script (40 respondents: a frozen copy of data/reference/survey.csv as the
#          reconstruction of commit e1d8ecb wrote it; the shipped reference data has since been regenerated);
# * lk:    tests/data/lane_keeping/survey.csv (24 synthetic respondents; EE3 reversed x -> 8 - x; AGE as covariate);
# * inv:   invariance_survey.csv beside this script (240 synthetic respondents of the paper's study with a style
#          column; written by tests/analysis/test_extended_reference.py).
# The measurement model is the `=~` lines of the study's model.lav; the latent SEM and the composite path model are
# the *_sem.lav and *_paths.lav files beside this script (written by analysis.extended from the model file, and
# compared with it by the test).
# Conventions:
# * polychoric: lavCor(ordered = items) (two-step, thresholds from the margins);
# * ordinal CFA: cfa(ordered = items, estimator = "ULSMV") and "WLSMV", std.all loadings (delta parameterisation);
# * ordinal omega: compRelSEM() on those fits (ord.scale = TRUE, obs.var = TRUE: Green & Yang 2009);
# * one-factor omega: compRelSEM() of cfa(estimator = "ML") of each construct with >= 3 items alone;
# * HTMT / HTMT2: semTools::htmt(htmt2 = FALSE / TRUE) on the item answers (absolute correlations);
# * latent SEM: sem(estimator = "ML"), std.all paths, R^2 (lavInspect "r2"), chisq, df, cfi, tli, rmsea, srmr;
# * path model on the composites (item means): the := indirect effects (unstandardized products), and the
#   standardized coefficients of each equation from lm() on scale()d variables;
# * full-collinearity VIF: 1 / (1 - R^2) of lm(composite ~ all other composites); Harman: first eigenvalue of
#   cor(items) / number of items;
# * invariance: cfa(group = "style", group.equal = c() / "loadings" / c("loadings", "intercepts")), ML:
#   chisq, df, cfi, tli, rmsea per step.

args <- commandArgs(trailingOnly = FALSE)
script <- sub("^--file=", "", args[grep("^--file=", args)])
here <- if (length(script)) dirname(normalizePath(script)) else "tests/data/r_reference"
repo <- normalizePath(file.path(here, "..", "..", ".."))
suppressPackageStartupMessages({library(lavaan); library(semTools)})

num <- function(x) if (is.na(x)) "" else sprintf("%.17g", x)
out <- character(0)
put <- function(dataset, quantity, key, value) {
  out <<- c(out, sprintf("%s,%s,%s,%s", dataset, quantity, key, num(as.numeric(value))))
}

measurement_of <- function(study) {
  lines <- sub("#.*$", "", readLines(file.path(repo, "studies", study, "model.lav")))
  trimws(lines[grepl("=~", lines)])
}
constructs_of <- function(measurement) {
  cs <- list()
  for (ln in measurement) {
    parts <- strsplit(ln, "=~", fixed = TRUE)[[1]]
    cs[[trimws(parts[1])]] <- trimws(strsplit(parts[2], "+", fixed = TRUE)[[1]])
  }
  cs
}

run <- function(tag, data, study) {
  measurement <- measurement_of(study)
  meas <- paste(measurement, collapse = "\n")
  cs <- constructs_of(measurement)
  items <- unlist(cs, use.names = FALSE)
  pc <- lavCor(data[, items], ordered = items)
  for (i in seq_along(items)) for (j in seq_along(items)) if (i < j)
    put(tag, "polychoric", paste0(items[i], "-", items[j]), pc[i, j])
  for (est in c("ULSMV", "WLSMV")) {
    f <- cfa(meas, data = data, ordered = items, estimator = est)
    s <- standardizedSolution(f)
    s <- s[s$op == "=~", ]
    for (r in seq_len(nrow(s))) put(tag, paste0("loading_", est), s$rhs[r], s$est.std[r])
    om <- compRelSEM(f)
    for (cn in names(om)) put(tag, paste0("omega_ordinal_", est), cn, om[[cn]])
  }
  fml <- cfa(meas, data = data, estimator = "ML")
  om <- compRelSEM(fml)
  for (cn in names(om)) put(tag, "omega_ml", cn, om[[cn]])
  for (cn in names(cs)) if (length(cs[[cn]]) >= 3) {
    f1 <- cfa(paste(cn, "=~", paste(cs[[cn]], collapse = " + ")), data = data, estimator = "ML")
    put(tag, "omega_one_factor", cn, compRelSEM(f1)[[1]])
  }
  h1 <- htmt(meas, data = data, htmt2 = FALSE)
  h2 <- htmt(meas, data = data, htmt2 = TRUE)
  nm <- names(cs)
  for (a in seq_along(nm)) for (b in seq_along(nm)) if (a < b) {
    put(tag, "htmt", paste0(nm[a], "-", nm[b]), h1[nm[b], nm[a]])
    put(tag, "htmt2", paste0(nm[a], "-", nm[b]), h2[nm[b], nm[a]])
  }
  sem_syntax <- paste(readLines(file.path(here, paste0(tag, "_sem.lav"))), collapse = "\n")
  fs <- sem(sem_syntax, data = data, estimator = "ML")
  s <- standardizedSolution(fs)
  s <- s[s$op == "~", ]
  for (r in seq_len(nrow(s))) put(tag, "sem_std", paste0(s$lhs[r], "~", s$rhs[r]), s$est.std[r])
  r2 <- lavInspect(fs, "r2")
  for (v in names(r2)) if (!(v %in% items)) put(tag, "sem_r2", v, r2[[v]])
  fm <- fitMeasures(fs, c("chisq", "df", "cfi", "tli", "rmsea", "srmr"))
  for (q in names(fm)) put(tag, "sem_fit", q, fm[[q]])

  comp <- data
  for (cn in names(cs)) comp[[cn]] <- rowMeans(data[, cs[[cn]]])
  path_syntax <- paste(readLines(file.path(here, paste0(tag, "_paths.lav"))), collapse = "\n")
  fp <- sem(path_syntax, data = comp, estimator = "ML")
  pe <- parameterEstimates(fp)
  pe <- pe[pe$op == ":=", ]
  for (r in seq_len(nrow(pe))) put(tag, "indirect_b", pe$lhs[r], pe$est[r])
  eqs <- strsplit(readLines(file.path(here, paste0(tag, "_paths.lav"))), "~", fixed = TRUE)
  for (eq in eqs) if (length(eq) == 2 && !grepl(":=", eq[1])) {
    dv <- trimws(eq[1])
    preds <- sub("^.*\\*", "", trimws(strsplit(eq[2], "+", fixed = TRUE)[[1]]))
    z <- as.data.frame(scale(comp[, c(dv, preds)]))
    co <- coef(lm(reformulate(preds, response = dv), data = z))
    for (p in preds) put(tag, "path_std", paste0(dv, "~", p), co[[p]])
  }
  for (cn in nm) {
    others <- setdiff(nm, cn)
    r2 <- summary(lm(reformulate(others, response = cn), data = comp))$r.squared
    put(tag, "full_vif", cn, 1 / (1 - r2))
  }
  put(tag, "harman", "first_share", eigen(cor(data[, items]))$values[1] / length(items))
}

paper <- read.csv(file.path(here, "survey.csv"), stringsAsFactors = FALSE)
run("paper", paper, "pedas_paper")
lk <- read.csv(file.path(repo, "tests", "data", "lane_keeping", "survey.csv"), stringsAsFactors = FALSE)
lk$EE3 <- 8 - lk$EE3
names(lk)[names(lk) == "AGE"] <- "age"
run("lk", lk, "lane_keeping")

inv <- read.csv(file.path(here, "invariance_survey.csv"), stringsAsFactors = FALSE)
meas <- paste(measurement_of("pedas_paper"), collapse = "\n")
steps <- list(configural = "", metric = "loadings", scalar = c("loadings", "intercepts"))
for (st in names(steps)) {
  f <- if (st == "configural") cfa(meas, data = inv, group = "style", estimator = "ML") else
    cfa(meas, data = inv, group = "style", group.equal = steps[[st]], estimator = "ML")
  fm <- fitMeasures(f, c("chisq", "df", "cfi", "tli", "rmsea"))
  for (q in names(fm)) put("inv", st, q, fm[[q]])
}

writeLines(c("dataset,quantity,key,value", out), file.path(here, "extended_reference.csv"))
cat("lavaan", as.character(packageVersion("lavaan")), "semTools", as.character(packageVersion("semTools")),
    ":", length(out), "values written to", file.path(here, "extended_reference.csv"), "\n")

# Reference values for tests/analysis/test_lavaan_reference.py: the lane-keeping example study analysed with lavaan (CFA)
# and lm() (hierarchical regressions), written to lavaan_reference.json beside this script.
#
#   Rscript tests/data/lane_keeping/lavaan_reference.R      (from the repository root; needs R and lavaan)
#
# Conventions matched to analysis/cfa.py and analysis/regression.py:
# * EE3 is reverse-coded in the raw answers: x -> 1 + 7 - x before anything else (the codebook's reverse_scored).
# * CFA: the measurement model (the `=~` lines of studies/lane_keeping/model.lav), lavaan's defaults: ML, the
#   first loading of each factor fixed to 1, correlated factors, likelihood "normal" (biased covariance, divisor
#   N) -- the same minimiser as semopy's MLW objective. Standardized loadings are std.all (independent of the
#   identification). Fit: chisq, df, cfi, tli, rmsea, srmr (lavaan's srmr = srmr_bentler without a mean structure).
# * Regressions: composites = mean of each construct's items after reversal; step 1 BI ~ age, step 2
#   BI ~ age + PE + EE + SI (the `~` lines of the model file); B, SE, t, two-sided p, beta = B sd(x)/sd(y), R^2,
#   adjusted R^2, Delta R^2 and the F change of each step against the one before (step 1 against the intercept-only
#   model) from anova().
# jsonlite is not required: the JSON is written by hand with 17 significant digits.

args <- commandArgs(trailingOnly = FALSE)
script <- sub("^--file=", "", args[grep("^--file=", args)])
here <- if (length(script)) dirname(normalizePath(script)) else "tests/data/lane_keeping"
repo <- normalizePath(file.path(here, "..", "..", ".."))
suppressPackageStartupMessages(library(lavaan))

survey <- read.csv(file.path(here, "survey.csv"), stringsAsFactors = FALSE)
people <- read.csv(file.path(here, "participants.csv"), stringsAsFactors = FALSE)
survey$EE3 <- 1 + 7 - survey$EE3
data <- merge(survey, people, by = "participant_id", sort = FALSE)
data <- data[match(survey$participant_id, data$participant_id), ]

lines <- sub("#.*$", "", readLines(file.path(repo, "studies", "lane_keeping", "model.lav")))
measurement <- trimws(lines[grepl("=~", lines)])
fit <- cfa(paste(measurement, collapse = "\n"), data = data, estimator = "ML")
std <- standardizedSolution(fit)
std <- std[std$op == "=~", ]
fm <- fitMeasures(fit, c("chisq", "df", "cfi", "tli", "rmsea", "srmr"))

constructs <- list()
for (ln in measurement) {
  parts <- strsplit(ln, "=~", fixed = TRUE)[[1]]
  constructs[[trimws(parts[1])]] <- trimws(strsplit(parts[2], "+", fixed = TRUE)[[1]])
}
for (cname in names(constructs)) data[[cname]] <- rowMeans(data[, constructs[[cname]]])

steps <- list(c("age"), c("age", "PE", "EE", "SI"))
num <- function(x) if (is.na(x)) "null" else sprintf("%.17g", x)
reg_rows <- c()
previous <- lm(BI ~ 1, data = data)
for (s in seq_along(steps)) {
  m <- lm(reformulate(steps[[s]], response = "BI"), data = data)
  co <- summary(m)$coefficients
  a <- anova(previous, m)
  r2 <- summary(m)$r.squared
  r2_old <- if (s == 1) 0 else summary(previous)$r.squared
  for (term in rownames(co)) {
    beta <- if (term == "(Intercept)") NA else co[term, 1] * sd(data[[term]]) / sd(data$BI)
    reg_rows <- c(reg_rows, sprintf(paste0(
      '    {"step": %d, "term": "%s", "b": %s, "se": %s, "t": %s, "p": %s, "beta": %s, "r2": %s, "adj_r2": %s, ',
      '"delta_r2": %s, "f_change": %s, "p_change": %s, "df1": %d, "df2": %d}'),
      s, term, num(co[term, 1]), num(co[term, 2]), num(co[term, 3]), num(co[term, 4]), num(beta), num(r2),
      num(summary(m)$adj.r.squared), num(r2 - r2_old), num(a$F[2]), num(a[["Pr(>F)"]][2]), as.integer(a$Df[2]),
      as.integer(a$Res.Df[2])))
  }
  previous <- m
}

load_rows <- sprintf('    {"construct": "%s", "item": "%s", "std_all": %s}', std$lhs, std$rhs,
                     vapply(std$est.std, num, ""))
json <- paste0(
  '{\n  "lavaan_version": "', as.character(packageVersion("lavaan")), '",\n',
  '  "r_version": "', paste(R.version$major, R.version$minor, sep = "."), '",\n',
  '  "n": ', nrow(data), ',\n',
  '  "loadings": [\n', paste(load_rows, collapse = ",\n"), '\n  ],\n',
  '  "fit": {"chisq": ', num(fm[["chisq"]]), ', "df": ', as.integer(fm[["df"]]), ', "cfi": ', num(fm[["cfi"]]),
  ', "tli": ', num(fm[["tli"]]), ', "rmsea": ', num(fm[["rmsea"]]), ', "srmr": ', num(fm[["srmr"]]), '},\n',
  '  "regressions": [\n', paste(reg_rows, collapse = ",\n"), '\n  ]\n}\n')
writeLines(json, file.path(here, "lavaan_reference.json"), sep = "")
print(std[, c("lhs", "op", "rhs", "est.std")], digits = 7)
print(fm, digits = 7)
cat("written", file.path(here, "lavaan_reference.json"), "\n")

# Reference values for tests/analysis/test_within.py: the within-subjects comparisons of the synthetic takeover-warning study
# (items.csv beside this script), written to within_reference.json beside this script.
#
#   Rscript tests/data/takeover/within_reference.R      (from anywhere; needs R, lme4 and afex)
#
# Conventions matched to analysis/survey/within.py:
# * Scores from the items as ticked: SUS (Brooke 1996) = 2.5 x (sum of odd items - 1 and of 5 - even items); raw
#   NASA-TLX = mean of the six subscales; trust = mean of the six items after 8 - x for trust2 and trust5.
#   (Computed here independently; score_max_diff records the largest difference to the committed scores.csv.)
# * Condition levels none, visual, audiovisual (none is the reference of the mixed model); period 1, 2, 3 a factor.
# * rm-ANOVA, Mauchly, GG/HF, Friedman and the paired tests on the complete cases (participants with all three
#   conditions: TOR-A19 is left out); descriptives on every row; lmer on the complete cases and on every row.
# * Pairs in the order none-visual, none-audiovisual, visual-audiovisual; differences a - b; Holm over the three
#   pairs of each test; dz = mean(a - b) / sd(a - b).
# * boundary.csv (a hand-made case whose REML random-intercept variance is 0): lmer value ~ condition +
#   (1 | participant), a singular fit.
# * afex: aov_ez with anova_table = list(correction = "none", es = c("pes", "ges")); Mauchly and the GG and HF
#   epsilons and corrected p from summary() (car's summary.Anova.mlm; its HF epsilon is not capped at 1, the
#   HF-corrected p uses min(1, HF)).
# jsonlite is not required: the JSON is written by hand with 17 significant digits.

args <- commandArgs(trailingOnly = FALSE)
script <- sub("^--file=", "", args[grep("^--file=", args)])
here <- if (length(script)) dirname(normalizePath(script)) else "tests/data/takeover"
suppressPackageStartupMessages({
  library(lme4)
  library(afex)
})

items <- read.csv(file.path(here, "items.csv"), stringsAsFactors = FALSE)
committed <- read.csv(file.path(here, "scores.csv"), stringsAsFactors = FALSE)
odd <- paste0("sus", c(1, 3, 5, 7, 9))
even <- paste0("sus", c(2, 4, 6, 8, 10))
tlx_items <- paste0("tlx_", c("mental", "physical", "temporal", "performance", "effort", "frustration"))
trust_items <- paste0("trust", 1:6)
trust <- items[, trust_items]
trust$trust2 <- 8 - trust$trust2
trust$trust5 <- 8 - trust$trust5
scores <- data.frame(
  participant = items$participant, period = items$period, condition = items$condition,
  sus = 2.5 * (rowSums(items[, odd] - 1) + rowSums(5 - items[, even])),
  tlx = rowMeans(items[, tlx_items]),
  trust = rowMeans(trust))

levels <- c("none", "visual", "audiovisual")
counts <- table(scores$participant)
complete_ids <- names(counts)[counts == length(levels)]
pairs <- combn(levels, 2)
num <- function(x) if (is.na(x)) "null" else sprintf("%.17g", x)
obj <- function(...) {
  kv <- list(...)
  paste0("{", paste(sprintf('"%s": %s', names(kv), unlist(kv)), collapse = ", "), "}")
}
str <- function(x) sprintf('"%s"', x)

lmer_json <- function(d, formula = value ~ condition + period + (1 | participant)) {
  fit <- suppressMessages(lmer(formula, data = d, REML = TRUE))
  co <- summary(fit)$coefficients  # afex attaches lmerTest: Estimate, Std. Error, df, t value, Pr(>|t|)
  vc <- as.data.frame(VarCorr(fit))
  terms <- vapply(rownames(co), function(t)
    obj(term = str(t), coef = num(co[t, "Estimate"]), se = num(co[t, "Std. Error"]), t = num(co[t, "t value"])),
    "")
  paste0('{"n_obs": ', nrow(d), ', "var_participant": ', num(vc$vcov[vc$grp == "participant"]),
         ', "var_residual": ', num(vc$vcov[vc$grp == "Residual"]), ', "singular": ',
         tolower(as.character(isSingular(fit))), ', "reml_criterion": ', num(REMLcrit(fit)),
         ',\n        "terms": [\n          ', paste(terms, collapse = ",\n          "), ']}')
}

blocks <- c()
score_diff <- c()
for (v in c("sus", "tlx", "trust")) {
  score_diff <- c(score_diff, sprintf('"%s": %s', v, num(max(abs(scores[[v]] - committed[[v]])))))
  all <- data.frame(participant = factor(scores$participant), condition = factor(scores$condition, levels = levels),
                    period = factor(scores$period), value = scores[[v]])
  d <- droplevels(all[all$participant %in% complete_ids, ])
  d <- d[order(d$participant, d$condition), ]

  desc <- vapply(levels, function(l) {
    x <- all$value[all$condition == l]
    q <- quantile(x, c(0.25, 0.75), type = 7)
    obj(condition = str(l), n = length(x), mean = num(mean(x)), sd = num(sd(x)), median = num(median(x)),
        q1 = num(q[[1]]), q3 = num(q[[2]]), iqr = num(IQR(x)), min = num(min(x)), max = num(max(x)))
  }, "")

  a <- summary(aov(value ~ condition + Error(participant / condition), data = d))
  within <- a[["Error: participant:condition"]][[1]]
  aov_json <- obj(f = num(within[["F value"]][1]), df1 = num(within[["Df"]][1]), df2 = num(within[["Df"]][2]),
                  p = num(within[["Pr(>F)"]][1]), ss = num(within[["Sum Sq"]][1]),
                  ss_error = num(within[["Sum Sq"]][2]))

  ez <- suppressMessages(aov_ez("participant", "value", d, within = "condition",
                                anova_table = list(correction = "none", es = c("pes", "ges"))))
  tab <- ez$anova_table
  s <- suppressWarnings(summary(ez))  # "HF eps > 1 treated as 1": the uncapped HF epsilon is kept below
  sph <- s$sphericity.tests
  adj <- s$pval.adjustments
  afex_json <- obj(f = num(tab[["F"]][1]), pes = num(tab[["pes"]][1]), ges = num(tab[["ges"]][1]),
                   mauchly_w = num(sph["condition", "Test statistic"]), mauchly_p = num(sph["condition", "p-value"]),
                   gg_eps = num(adj["condition", "GG eps"]), gg_p = num(adj["condition", "Pr(>F[GG])"]),
                   hf_eps = num(adj["condition", "HF eps"]), hf_p = num(adj["condition", "Pr(>F[HF])"]))

  fr <- friedman.test(value ~ condition | participant, data = d)
  n <- length(complete_ids)
  friedman_json <- obj(chi2 = num(unname(fr$statistic)), df = num(unname(fr$parameter)), p = num(fr$p.value),
                       kendall_w = num(unname(fr$statistic) / (n * (length(levels) - 1))), n = n)

  pair_rows <- list()
  for (j in seq_len(ncol(pairs))) {
    x <- d$value[d$condition == pairs[1, j]]
    y <- d$value[d$condition == pairs[2, j]]
    tt <- t.test(x, y, paired = TRUE)
    ww <- suppressWarnings(wilcox.test(x, y, paired = TRUE))
    pair_rows[[j]] <- list(a = pairs[1, j], b = pairs[2, j], t = unname(tt$statistic), df = unname(tt$parameter),
                           p_t = tt$p.value, v = unname(ww$statistic), p_w = ww$p.value,
                           mean_diff = mean(x - y), dz = mean(x - y) / sd(x - y),
                           n_nonzero = sum(x != y), ties = any(duplicated(abs(x - y)[x != y])))
  }
  p_t_holm <- p.adjust(vapply(pair_rows, function(r) r$p_t, 0), method = "holm")
  p_w_holm <- p.adjust(vapply(pair_rows, function(r) r$p_w, 0), method = "holm")
  pair_json <- vapply(seq_along(pair_rows), function(j) {
    r <- pair_rows[[j]]
    obj(a = str(r$a), b = str(r$b), t = num(r$t), df = num(r$df), p_t = num(r$p_t), p_t_holm = num(p_t_holm[j]),
        v = num(r$v), p_w = num(r$p_w), p_w_holm = num(p_w_holm[j]), mean_diff = num(r$mean_diff),
        dz = num(r$dz), n_nonzero = r$n_nonzero, ties = tolower(as.character(r$ties)))
  }, "")

  blocks <- c(blocks, paste0(
    '    "', v, '": {\n',
    '      "n_complete": ', n, ',\n',
    '      "descriptives": [\n        ', paste(desc, collapse = ",\n        "), '],\n',
    '      "aov": ', aov_json, ',\n',
    '      "afex": ', afex_json, ',\n',
    '      "friedman": ', friedman_json, ',\n',
    '      "pairs": [\n        ', paste(pair_json, collapse = ",\n        "), '],\n',
    '      "lmer_complete": ', lmer_json(d), ',\n',
    '      "lmer_all": ', lmer_json(all), '}'))
}

# boundary.csv: every participant's three values have the same mean, so the REML random-intercept variance is 0
# (a singular fit; the fixed effects are those of lm())
boundary <- read.csv(file.path(here, "boundary.csv"), stringsAsFactors = FALSE)
boundary$participant <- factor(boundary$participant)
boundary$condition <- factor(boundary$condition)
boundary_json <- lmer_json(boundary, value ~ condition + (1 | participant))

json <- paste0(
  '{\n  "r_version": "', paste(R.version$major, R.version$minor, sep = "."), '",\n',
  '  "afex_version": "', as.character(packageVersion("afex")), '",\n',
  '  "lme4_version": "', as.character(packageVersion("lme4")), '",\n',
  '  "complete_participants": ', length(complete_ids), ',\n',
  '  "score_max_diff": {', paste(score_diff, collapse = ", "), '},\n',
  '  "variables": {\n', paste(blocks, collapse = ",\n"), '\n  },\n',
  '  "boundary": ', boundary_json, '\n}\n')
writeLines(json, file.path(here, "within_reference.json"), sep = "")
cat("written", file.path(here, "within_reference.json"), "\n")

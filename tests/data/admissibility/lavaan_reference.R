# Reference values for tests/analysis/test_admissibility.py: what lavaan 0.6-14 says about the two improper-solution data
# sets beside this script (generate.py), written to lavaan_reference.csv (columns dataset, quantity, key, value,
# text; 17 significant digits).
#
#   Rscript tests/data/admissibility/lavaan_reference.R      (from the repository root; needs lavaan)
#
# Conventions as the analysis: the final measurement model of studies/pedas_paper/model.lav and the structural
# paths of tests/data/r_reference/paper_sem.lav; complete rows only (listwise, 32 of 35); ML (sem) on the items
# as numbers; ordinal: cfa(ordered = items, estimator = "ULSMV"/"WLSMV") on the item columns of the whole data set
# (35 rows; lavaan deletes listwise itself), so an item's categories are the answers it has anywhere.

args <- commandArgs(trailingOnly = FALSE)
script <- sub("^--file=", "", args[grep("^--file=", args)])
here <- if (length(script)) dirname(normalizePath(script)) else "tests/data/admissibility"
repo <- normalizePath(file.path(here, "..", "..", ".."))
suppressPackageStartupMessages(library(lavaan))

num <- function(x) if (is.na(x)) "" else sprintf("%.17g", x)
out <- "dataset,quantity,key,value,text"
put <- function(dataset, quantity, key, value = NA, text = "") {
  text <- gsub("[\r\n\"]+", " ", text)
  out <<- c(out, sprintf("%s,%s,%s,%s,\"%s\"", dataset, quantity, key, num(as.numeric(value)), trimws(text)))
}
caught <- function(expr) {
  msgs <- character(0)
  val <- withCallingHandlers(tryCatch(expr, error = function(e) { msgs <<- c(msgs, paste("ERROR:", conditionMessage(e))); NULL }),
                             warning = function(w) { msgs <<- c(msgs, conditionMessage(w)); invokeRestart("muffleWarning") })
  list(value = val, messages = msgs)
}

sem_syntax <- paste(readLines(file.path(repo, "tests", "data", "r_reference", "paper_sem.lav")), collapse = "\n")
meas <- paste(grep("=~", readLines(file.path(repo, "tests", "data", "r_reference", "paper_sem.lav")), value = TRUE),
              collapse = "\n")
items <- trimws(unlist(strsplit(sub(".*=~", "", grep("=~", strsplit(meas, "\n")[[1]], value = TRUE)), "+", fixed = TRUE)))

for (ds in c("heywood", "empty_category")) {
  data <- read.csv(file.path(here, paste0("set_b_", ds, ".csv")))
  scaled <- setdiff(names(data), "participant_id")
  complete <- data[complete.cases(data[, scaled]), ]
  put(ds, "n_complete", "", nrow(complete))
  # ML SEM on the complete rows
  r <- caught(sem(sem_syntax, data = complete, estimator = "ML"))
  for (m in r$messages) put(ds, "sem_message", "", NA, m)
  if (!is.null(r$value)) {
    pe <- parameterEstimates(r$value)
    for (it in items) put(ds, "sem_error_var", it, pe$est[pe$lhs == it & pe$op == "~~" & pe$rhs == it])
    put(ds, "sem_converged", "", as.numeric(lavInspect(r$value, "converged")))
  }
  # ordinal CFA: categories from the whole column, then listwise
  for (est in c("ULSMV", "WLSMV")) {
    # lavaan's own listwise deletion (missing = "listwise", its default here) of the whole data set, as a user
    # calls it: ordered= levels come from the whole columns
    r <- caught(cfa(meas, data = data[, scaled], ordered = items, estimator = est))
    for (m in r$messages) put(ds, paste0("ordinal_message_", est), "", NA, m)
    if (!is.null(r$value)) {
      lv <- lavInspect(r$value, "cor.lv")
      put(ds, paste0("ordinal_cor_lv_", est), "PU-ATT", lv["PU", "ATT"])
      put(ds, paste0("ordinal_min_eigen_", est), "", min(eigen(lavInspect(r$value, "cov.lv"))$values))
      put(ds, paste0("ordinal_srmr_", est), "", fitMeasures(r$value, "srmr"))
    }
  }
}
writeLines(out, file.path(here, "lavaan_reference.csv"))

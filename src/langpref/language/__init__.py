"""Language side of langpref: the utterance bank (per env, feature and direction, with train/val/test paraphrase
splits) and the loader for users' own utterance files. See `langpref.language.bank`."""
